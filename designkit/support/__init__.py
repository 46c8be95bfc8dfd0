"""What every part of designkit leans on: input checks (:mod:`.validate`), atomic file writing
(:mod:`.atomic`), line-wise progress bars (:mod:`.progress`) and one-thread BLAS sections
(:mod:`.blas`)."""
