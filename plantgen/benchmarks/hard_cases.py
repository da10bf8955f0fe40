"""Print the hard-case table: each case's worst errors in float64 and float32.

Run: ``python -m plantgen.benchmarks.hard_cases [--rays N] [--no-march]``. Columns are
described in :mod:`plantgen.geometry.rays.stability`.
"""

from __future__ import annotations

import argparse

from ..geometry.rays.stability import HARD_CASES, evaluate_case, format_table


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=200)
    parser.add_argument("--no-march", action="store_true", help="skip brute-force marching")
    args = parser.parse_args(argv)
    results = [evaluate_case(c, args.rays, march=not args.no_march) for c in HARD_CASES]
    print(format_table(results))


if __name__ == "__main__":
    main()
