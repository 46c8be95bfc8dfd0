"""The thesis' learned inverse (section 3.2.2): a small MLP from one sensor's field to the magnet's
position relative to that sensor.

Features: the field's direction (3) and log10 |B| (B in T); two tanh layers; outputs scaled to
the training box, m. Trained offline (designkit.calibration.learned_inverse.train_learned_inverse) and
stored in an .npz weights file; inference here is numpy only.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadInputError


@dataclass(frozen=True)
class LearnedInverse:
    """MLP: features (u_B (3), log10 |B|) -> magnet position relative to the sensor, m."""

    weights: tuple
    feature_mean: np.ndarray
    feature_std: np.ndarray
    box_lower_m: np.ndarray
    box_upper_m: np.ndarray
    log_b_range: tuple
    design_sha256: str

    @classmethod
    def load(cls, path) -> "LearnedInverse":
        p = Path(path)
        if not p.is_file():
            raise BadInputError("weights", "a path to an existing learned-inverse .npz", str(p))
        try:
            with np.load(p, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                nl = int(meta["layers"])
                w = tuple((z[f"W{k}"].astype(float), z[f"b{k}"].astype(float)) for k in range(nl))
                out = cls(w, z["feature_mean"].astype(float), z["feature_std"].astype(float),
                          z["box_lower_m"].astype(float), z["box_upper_m"].astype(float),
                          tuple(meta["log_b_range"]), meta["design_sha256"])
        except (KeyError, ValueError, OSError, EOFError) as exc:
            raise BadInputError("weights", "a learned-inverse file written by "
                                "designkit.calibration.learned_inverse"
                                f" ({type(exc).__name__}: {exc})", str(p)) from None
        return out

    def save(self, path) -> None:
        arrays = {f"W{k}": w for k, (w, _) in enumerate(self.weights)}
        arrays.update({f"b{k}": b for k, (_, b) in enumerate(self.weights)})
        meta = {"layers": len(self.weights), "log_b_range": list(self.log_b_range),
                "design_sha256": self.design_sha256, "format": "designkit-learned-inverse"}
        np.savez(path, feature_mean=self.feature_mean, feature_std=self.feature_std,
                 box_lower_m=self.box_lower_m, box_upper_m=self.box_upper_m,
                 meta=json.dumps(meta), **arrays)

    @staticmethod
    def features(b: np.ndarray) -> np.ndarray:
        """(k, 3) T -> (k, 4)."""
        n = np.linalg.norm(b, axis=-1)
        return np.c_[b / n[:, None], np.log10(n)]

    def raw(self, b: np.ndarray) -> np.ndarray:
        """Unclipped network output (k, 3) m for fields (k, 3) T."""
        h = (self.features(b) - self.feature_mean) / self.feature_std
        for k, (w, bias) in enumerate(self.weights):
            h = h @ w + bias
            if k < len(self.weights) - 1:
                h = np.tanh(h)
        c = 0.5 * (self.box_lower_m + self.box_upper_m)
        return c + h * 0.5 * (self.box_upper_m - self.box_lower_m)

    def __call__(self, b: np.ndarray) -> tuple[np.ndarray, bool]:
        """(3,) T -> (relative position (3,) m inside the training box, inside flag)."""
        b = np.asarray(b, float).reshape(1, 3)
        lb = math.log10(float(np.linalg.norm(b)) or 1e-30)
        rel = self.raw(b)[0]
        inside = bool(np.all(rel >= self.box_lower_m) and np.all(rel <= self.box_upper_m)
                      and self.log_b_range[0] <= lb <= self.log_b_range[1])
        return np.clip(rel, self.box_lower_m, self.box_upper_m), inside
