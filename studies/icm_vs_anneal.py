"""ICM vs simulated annealing on 32-level grey exemplars.

Usage: python studies/icm_vs_anneal.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study icm_vs_anneal ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("icm_vs_anneal")
