"""ICM cooling, xi = -1 vs -3 and full vs 95 % stop, with global temperature curves.

Usage: python studies/cooling.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study cooling ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("cooling")
