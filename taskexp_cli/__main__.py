"""python -m taskexp_cli: the same command as `python taskexp.py` and `taskexp`."""
from taskexp_cli import main

main()
