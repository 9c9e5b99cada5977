"""Compare two folders of fixed-seed runs (scripts/fixed_seed_runs.sh) row by row, leaving out
the timing fields: prints each run's verdict and exits 1 if any row differs."""

import json
import sys
from pathlib import Path

TIMING = ("walltime_s", "env_steps_per_s")


def rows(path: Path) -> list[dict]:
    return [{k: v for k, v in json.loads(line).items() if k not in TIMING} for line in path.read_text().splitlines()]


def same(a, b) -> bool:
    return a == b or (a != a and b != b)  # NaN equals NaN here


def main(before: str, after: str) -> int:
    failed = 0
    for run in ("goal", "nav", "terrain"):
        a, b = (rows(Path(folder) / run / "metrics.jsonl") for folder in (before, after))
        diffs = [(i, k) for i, (ra, rb) in enumerate(zip(a, b)) for k in ra.keys() | rb.keys()
                 if not same(ra.get(k), rb.get(k))]
        ok = len(a) == len(b) and not diffs
        failed += not ok
        print(f"{run}: {len(a)} rows against {len(b)}: {'bit-identical' if ok else f'differ at {diffs[:5]}'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
