"""Colour exemplars with annealing and ML_H2b.

Usage: python studies/colour.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study colour ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("colour")
