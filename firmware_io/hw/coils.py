"""CoilDriver: nine signed coil voltages or currents -> PWM and DIR outputs on two PCA9685 boards.

Each coil needs two outputs (MD10C PWM = magnitude, DIR = direction), so nine coils need 18 > 16
outputs and two boards. A coil's PWM and DIR sit on one chip, so the STOP of that chip's single
block write changes both together; the default wiring puts coils 0-7 on board 0 (PWM on even
channels, DIR on the odd one above) and coil 8 on board 1, channels 0 and 1.

Safe state: if any write of a command fails, every board gets ALL_LED_OFF (each tried twice), an
optional ``kill_switch`` (e.g. a GPIO driving OE high) is called if that could not be confirmed,
and :class:`firmware_io.errors.CoilWriteError` says what failed and what state the coils are in.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .pca9685 import PCA9685, ChannelValue
from ..errors import BadInputError, CoilWriteError
from .driver import CoilDrive, DriveCommand, current_to_command, voltage_to_command


Plan = tuple[list[DriveCommand], list[dict[int, ChannelValue]], list[dict[int, ChannelValue]],
             list[int]]
"""What :meth:`CoilDriver.plan` returns: the commands, the first and second writes per board,
and the coils that reverse under current."""


@dataclass(frozen=True)
class CoilOutput:
    """Where one coil's MD10C is wired.

    Attributes
    ----------
    board : int
        Index into the CoilDriver's boards.
    pwm_channel, dir_channel : int
        PCA9685 channels (0..15) of the MD10C PWM and DIR inputs, on the same board.
    forward_dir_level : {'low', 'high'}
        DIR level that makes a positive current (CytronMotorDriver: low). Flip it for a coil
        wired the other way round instead of rewiring.
    """

    board: int
    pwm_channel: int
    dir_channel: int
    forward_dir_level: Literal["low", "high"] = "low"


def default_coil_wiring(n_coils: int = 9) -> tuple[CoilOutput, ...]:
    """Coils 0-7 on board 0 (PWM 2k, DIR 2k+1), coils 8.. on board 1 in the same pattern."""
    return tuple(CoilOutput(k // 8, 2 * (k % 8), 2 * (k % 8) + 1) for k in range(n_coils))


@dataclass(frozen=True)
class CoilCommandResult:
    """What a :meth:`CoilDriver.command` call put on the outputs.

    Attributes
    ----------
    current_a : ndarray, shape (n_coils,), A
        Steady currents the written duties produce (signed, clamped, quantised).
    voltage_v : ndarray, shape (n_coils,), V
        Average voltages the written duties apply (signed, clamped, quantised).
    clamped : ndarray, shape (n_coils,), bool
        Requests that exceeded a coil's limit.
    reversed_coils : tuple of int
        Coils whose direction changed (written in two steps).
    commands : tuple of DriveCommand
    """

    current_a: np.ndarray
    clamped: np.ndarray
    reversed_coils: tuple[int, ...]
    commands: tuple[DriveCommand, ...]
    voltage_v: np.ndarray


class CoilDriver:
    """Signed coil currents -> MD10C PWM/DIR on PCA9685 boards.

    Parameters
    ----------
    boards : sequence of PCA9685
    drives : CoilDrive or sequence of CoilDrive (one per coil)
    wiring : sequence of CoilOutput, optional
        Default :func:`default_coil_wiring` for ``len(drives)`` coils (9 if one drive is given).
    reversal_dwell_s : float, optional
        Time between the "PWM off + new DIR" write and the new PWM write on a reversal, s.
        Default: one PWM period, because the PCA9685 applies new counts only at the end of the
        running period, so a shorter gap could skip the off period altogether.
    kill_switch : callable, optional
        Called when switching off could not be confirmed (e.g. drive the OE pins high).
    sleep : callable
        ``sleep(seconds)``.
    """

    def __init__(self, boards: Sequence[PCA9685], drives: CoilDrive | Sequence[CoilDrive],
                 wiring: Sequence[CoilOutput] | None = None, *,
                 reversal_dwell_s: float | None = None,
                 kill_switch: Callable[[], None] | None = None,
                 sleep: Callable[[float], None] = time.sleep):
        self.boards = tuple(boards)
        if not self.boards:
            raise BadInputError("boards", "at least one PCA9685", boards)
        if isinstance(drives, CoilDrive):
            n = len(wiring) if wiring is not None else 9
            drives = (drives,) * n
        self.drives = tuple(drives)
        self.wiring = tuple(wiring) if wiring is not None else default_coil_wiring(len(self.drives))
        if len(self.wiring) != len(self.drives):
            raise BadInputError("wiring", f"one CoilOutput per coil ({len(self.drives)})", len(self.wiring))
        used: set[tuple[int, int]] = set()
        for k, w in enumerate(self.wiring):
            if not 0 <= w.board < len(self.boards):
                raise BadInputError(f"wiring[{k}].board", f"in 0..{len(self.boards) - 1}", w.board)
            for ch in (w.pwm_channel, w.dir_channel):
                if not 0 <= ch <= 15:
                    raise BadInputError(f"wiring[{k}] channel", "in 0..15", ch)
                if (w.board, ch) in used:
                    raise BadInputError(f"wiring[{k}] channel", "not used by another coil output",
                                        (w.board, ch))
                used.add((w.board, ch))
        if reversal_dwell_s is not None and not reversal_dwell_s >= 0:
            raise BadInputError("reversal_dwell_s", ">= 0 s", reversal_dwell_s)
        self.reversal_dwell_s = reversal_dwell_s
        self.kill_switch = kill_switch
        self.sleep = sleep
        self.n_coils = len(self.wiring)
        # DIR level last written per coil; None = unknown (before initialize)
        self._dir_level: list[Literal["low", "high"] | None] = [None] * self.n_coils
        self._duty: list[int] = [0] * self.n_coils

    # -- setup and safe state ----------------------------------------------------------------
    def initialize(self, pwm_frequency_hz: float = 1526.0) -> None:
        """Initialise every board (all outputs off, ALLCALL cleared, PWM frequency set)."""
        try:
            for b in self.boards:
                b.initialize(pwm_frequency_hz)
        except OSError as exc:
            self._fail(exc, "initialisation")
        self._dir_level = ["low"] * self.n_coils
        self._duty = [0] * self.n_coils

    def all_off(self) -> list[str]:
        """Switch every output of every board off; return the boards that did not confirm."""
        unconfirmed = []
        for b in self.boards:
            for _ in range(2):
                try:
                    b.all_off()
                    break
                except OSError:
                    continue
            else:
                unconfirmed.append(f"0x{b.address:02X}")
        self._dir_level = ["low" if not unconfirmed else None for _ in range(self.n_coils)]
        self._duty = [0] * self.n_coils
        if unconfirmed and self.kill_switch is not None:
            self.kill_switch()
        return unconfirmed

    def _fail(self, exc: OSError, doing: str) -> None:
        unconfirmed = self.all_off()
        boards = ", ".join(f"0x{b.address:02X}" for b in self.boards)
        if unconfirmed:
            state = (f"switching off was NOT confirmed on {', '.join(unconfirmed)}"
                     + ("; kill switch called" if self.kill_switch else
                        ": drive the PCA9685 OE pin high or remove motor power"))
            safe = "unconfirmed"
        else:
            state = f"all {self.n_coils} coils were switched off (ALL_LED_OFF acknowledged by {boards})"
            safe = "all_off_confirmed"
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise CoilWriteError(exc.errno, f"Coil {doing} failed: {reason}; {state}.",
                             safe_state=safe) from exc

    # -- the command ---------------------------------------------------------------------------
    def plan(self, currents_a: Sequence[float] | np.ndarray) -> Plan:
        """Work out the writes for a current command without touching the bus.

        Returns
        -------
        commands, first_writes, second_writes, reversed_coils
            ``first_writes[b]`` / ``second_writes[b]`` are the channel maps for board b (the
            second step exists only for boards with a reversing coil).
        """
        arr = self._checked(currents_a, "currents_a", "currents in A")
        return self._plan([current_to_command(float(i), d) for i, d in zip(arr, self.drives)])

    def plan_voltage(self, voltages_v: Sequence[float] | np.ndarray) -> Plan:
        """:meth:`plan` for average coil voltages (shape (n_coils,), V, signed)."""
        arr = self._checked(voltages_v, "voltages_v", "voltages in V")
        return self._plan([voltage_to_command(float(v), d) for v, d in zip(arr, self.drives)])

    def _checked(self, values, name: str, what: str) -> np.ndarray:
        arr = np.asarray(values, dtype=float)
        if arr.shape != (self.n_coils,) or not np.all(np.isfinite(arr)):
            raise BadInputError(name, f"{self.n_coils} finite {what}", values)
        return arr

    def _plan(self, commands: list[DriveCommand]) -> Plan:
        first: list[dict[int, ChannelValue]] = [{} for _ in self.boards]
        second: list[dict[int, ChannelValue]] = [{} for _ in self.boards]
        reversed_coils = []
        for k, (cmd, w) in enumerate(zip(commands, self.wiring)):
            reverse_level: Literal["low", "high"] = "high" if w.forward_dir_level == "low" else "low"
            level = w.forward_dir_level if cmd.direction == "forward" else reverse_level
            prev = self._dir_level[k]
            if cmd.duty_counts == 0 and prev is not None:
                level = prev  # no current: leave DIR alone rather than toggle it for nothing
            dir_value: ChannelValue = "on" if level == "high" else "off"
            if prev is not None and level != prev and self._duty[k] > 0:
                # reversal under current: PWM off with the new DIR in one STOP, new PWM after
                first[w.board][w.pwm_channel] = "off"
                first[w.board][w.dir_channel] = dir_value
                second[w.board][w.pwm_channel] = cmd.pwm_value
                reversed_coils.append(k)
            else:
                first[w.board][w.pwm_channel] = cmd.pwm_value
                first[w.board][w.dir_channel] = dir_value
        return commands, first, second, reversed_coils

    def command(self, currents_a: Sequence[float] | np.ndarray) -> CoilCommandResult:
        """Drive the coils to ``currents_a`` (shape (n_coils,), A, signed).

        One block write per board; a board with a coil reversing under current gets a second
        write after :attr:`reversal_dwell_s`. Raises :class:`CoilWriteError` (all coils off)
        if any write fails.
        """
        return self._write(*self.plan(currents_a))

    def command_voltage(self, voltages_v: Sequence[float] | np.ndarray) -> CoilCommandResult:
        """Apply the average voltages ``voltages_v`` (shape (n_coils,), V, signed): the duty is
        ``|V| / Vs``. Writes and failure as :meth:`command`."""
        return self._write(*self.plan_voltage(voltages_v))

    def _write(self, commands, first, second, reversed_coils) -> CoilCommandResult:
        try:
            for b, values in zip(self.boards, first):
                if values:
                    b.set_channels(values)
            if reversed_coils:
                self.sleep(self._dwell())
                for b, values in zip(self.boards, second):
                    if values:
                        b.set_channels(values)
        except OSError as exc:
            self._fail(exc, "command")
        for k, (cmd, w) in enumerate(zip(commands, self.wiring)):
            value = first[w.board][w.dir_channel]
            self._dir_level[k] = "high" if value == "on" else "low"
            self._duty[k] = cmd.duty_counts
        return CoilCommandResult(
            current_a=np.array([c.current_a for c in commands]),
            clamped=np.array([c.clamped for c in commands]),
            reversed_coils=tuple(reversed_coils),
            commands=tuple(commands),
            voltage_v=np.array([c.voltage_v for c in commands]),
        )

    def _dwell(self) -> float:
        if self.reversal_dwell_s is not None:
            return self.reversal_dwell_s
        freqs = [b.frequency_hz for b in self.boards if b.frequency_hz]
        return 1.0 / min(freqs) if freqs else 1.0 / 24.0  # slowest possible PCA9685 period
