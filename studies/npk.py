"""ML_H2b (annealing) vs NP_K on ~15 real exemplars with the three metrics.

Usage: python studies/npk.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study npk ...'; --help lists every option). See studies/README.md.
"""

import pathlib
import sys

try:
    import npmrf3d  # noqa: F401
except ImportError:  # running from a source checkout that is not installed
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from npmrf3d.studies.cli import study_main

if __name__ == "__main__":
    sys.exit(study_main("npk"))
