"""Reference cross-check (issue #38, item 1): our CPO, PPO-Lagrangian and SAC-Lagrangian against OmniSafe's CPO,
PPOLag and SACLag, on the detect role beside the shipped decoy, the same budget, 3 seeds each, the same fresh
evaluation layouts (mission k: layout seed 2600001 + k).

    . .venv/bin/activate
    nice -n 5 python benchmarks/crosscheck_omnisafe.py --epochs 50 --steps-per-epoch 4000 --seeds 0,1,2
    python benchmarks/crosscheck_omnisafe.py --report          # pool the seeds: markdown table

Runs in the project's environment; OmniSafe's side runs in OmniSafe's (``--omnisafe-python``, default
the interpreter of benchmarks/omnisafe_env.py's environment, which that script builds). Every finished (impl, algo,
seed) row is written to ``--rows`` at once (default outside the checkout, benchmarks/output.py; the committed rows are
benchmarks/results/crosscheck_omnisafe.json) and skipped on a
rerun; a run killed part-way resumes (ours with --resume) or starts again (OmniSafe). Run directories: ``--work``
(default runs/crosscheck). What is aligned between the sides and what is not: benchmarks/crosscheck/README.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the benchmarks.crosscheck package of this checkout

from benchmarks.crosscheck.driver import main  # noqa: E402
from tssac_core.common.cli import run  # noqa: E402

if __name__ == "__main__":
    sys.exit(run(main))
