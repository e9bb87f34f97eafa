"""Speed suite: time to reach ``path``'s 64-spp error on the suite's eighteen scenes.

The measurement lives in :mod:`draaw_mi.bench.speed` (also ``draaw-mi bench --suite speed``);
see its docstring for the method. Usage::

    .venv/bin/python benchmarks/speed_suite.py                      # 128 and 256, all scenes
    .venv/bin/python benchmarks/speed_suite.py --res 128 --scenes cornell,metal_018 --out ''

The report goes to ``benchmarks/results/speed_suite_latest.md`` unless ``--out`` says otherwise
(``''``: printed only); ``benchmarks/results/speed_suite.md`` is the hand-curated record.
"""
import sys

from draaw_mi.bench.speed import main

if __name__ == "__main__":
    sys.exit(main())
