"""python -m taskexp_cli: the same command as `python taskexp.py` and `taskexp`."""
from taskexp_cli import main

if __name__ == "__main__":         # importing this module (pkgutil.walk_packages does) runs nothing
    main()
