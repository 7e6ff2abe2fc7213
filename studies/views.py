"""Two vs three constrained views on layered exemplars.

Usage: python studies/views.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study views ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("views")
