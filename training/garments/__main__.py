"""``python -m training.garments [ids...]``: rebuild the garment catalog (all ids by default)."""

import sys

from training.garments.build import build_catalog

if __name__ == "__main__":
    build_catalog(ids=sys.argv[1:] or None)
