"""2D -> 3D ground truth against a real volume (needs --volume FILE).

Usage: python studies/groundtruth.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study groundtruth ...'; --help lists every option). See studies/README.md.
"""

from _study import main

if __name__ == "__main__":
    main("groundtruth")
