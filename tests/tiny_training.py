"""Training command lines small enough for a test: a few dozen decisions per epoch, a tiny network, one thread."""

from __future__ import annotations


def tiny_args(
    *,
    epochs: int | None = 1,
    steps: int = 40,
    warmup: int = 20,
    envs: int = 2,
    validation: int = 0,
    hidden: str = "[16,16]",
    batch: int = 16,
) -> list[str]:
    """``tssac_core.train`` flags for a sac_lag decoy run of ``epochs`` epochs of ``steps`` decisions
    (``epochs=None`` leaves the count to the caller), random actions and no update for the first ``warmup``."""
    args = [
        "--algo",
        "sac_lag",
        "--roles",
        "decoy",
        "--steps-per-epoch",
        str(steps),
        "--start-steps",
        str(warmup),
        "--update-after",
        str(warmup),
        "--envs",
        str(envs),
        "--validation-episodes",
        str(validation),
        "--set",
        f"hidden_sizes={hidden}",
        "--set",
        f"batch_size={batch}",
        "--threads",
        "1",
        "--no-progress",
    ]
    return args if epochs is None else [*args, "--epochs", str(epochs)]
