"""Heuristics compared (ML_H1a, ML_H1b, ML_H2a, ML_H2b).

Usage: python studies/heuristics.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study heuristics ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("heuristics")
