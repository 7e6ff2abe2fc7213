"""ML_H2b (annealing) vs NP_K on ~15 real exemplars with the three metrics.

Usage: python studies/npk.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study npk ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("npk")
