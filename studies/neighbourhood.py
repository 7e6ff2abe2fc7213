"""Neighbourhood size (9x9, 11x11) crossed with 1/8 vs 8/8 up-sampling.

Usage: python studies/neighbourhood.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study neighbourhood ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("neighbourhood")
