"""python -m exercises {ex1..ex8 [NOTEBOOK] | all [DIR] | release OUT_DIR [SRC_DIR]}"""
import sys

from .notebooks import main

sys.exit(main())
