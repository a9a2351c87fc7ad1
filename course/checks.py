"""course/checks.py -- the check of each exercise, by its name: what a notebook's
graded cell, the command line and the kit's recording of cases run."""
from .ex1 import check_ex1
from .ex2 import check_ex2
from .ex3 import check_ex3
from .ex4 import check_ex4
from .ex5 import check_ex5
from .ex6 import check_ex6
from .ex7 import check_ex7
from .ex8 import check_ex8
from .ex9 import check_ex9
from .ex10 import check_ex10
from .ex11 import check_ex11
from .ex12 import check_ex12

CHECKS = dict(ex1=check_ex1, ex2=check_ex2, ex3=check_ex3, ex4=check_ex4, ex5=check_ex5,
              ex6=check_ex6, ex7=check_ex7, ex8=check_ex8,
              ex9=check_ex9, ex10=check_ex10, ex11=check_ex11,
              ex12=check_ex12)
