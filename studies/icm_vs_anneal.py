"""ICM vs simulated annealing on 32-level grey exemplars.

Usage: python studies/icm_vs_anneal.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study icm_vs_anneal ...'; --help lists every option). See studies/README.md.
"""

import pathlib
import sys

try:
    import npmrf3d  # noqa: F401
except ImportError:  # running from a source checkout that is not installed
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from npmrf3d.studies.cli import study_main

if __name__ == "__main__":
    sys.exit(study_main("icm_vs_anneal"))
