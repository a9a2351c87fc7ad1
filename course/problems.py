"""course/problems.py -- the problem set as data: each exercise's notebook, the
functions the student writes in it (in the order its check takes them), and its points (those of its
graded cell; tests/test_exercises.py checks they agree), and the points of the answers graded by
hand."""

NOTEBOOKS = {"ex1": "ex01_mlp_backward.ipynb", "ex2": "ex02_logprob_entropy.ipynb",
             "ex3": "ex03_gae.ipynb", "ex4": "ex04_ppo_loss.ipynb", "ex5": "ex05_alter.ipynb",
             "ex6": "ex06_select_relabel.ipynb", "ex7": "ex07_base_policy.ipynb",
             "ex8": "ex08_attention_backward.ipynb", "ex9": "ex09_expansion_step.ipynb",
             "ex10": "ex10_distillation_data.ipynb", "ex11": "ex11_ablations.ipynb",
             "ex12": "ex12_capstone.ipynb"}
FUNCTIONS = {"ex1": ["mlp_backward"],
             "ex2": ["logp_entropy", "logp_entropy_backward", "log_softmax"],
             "ex3": ["gae"], "ex4": ["ppo_loss"], "ex5": ["alter"],
             "ex6": ["select_goal", "relabel"], "ex8": ["attention_backward"],
             "ex9": ["join", "expansion_step"],
             "ex10": ["distillation_data", "distillation_tasks"],
             "ex11": ["select_goal", "one_drop_away"]}
POINTS = {"ex1": 2, "ex2": 3, "ex3": 2, "ex4": 2, "ex5": 2, "ex6": 2, "ex7": 3, "ex8": 3,
          "ex9": 3, "ex10": 2, "ex11": 2,
          "ex12": 4}
# the points of the answers an instructor grades by hand (nbgrader's manually graded cells), on
# top of POINTS: ex11's prediction and explanation of the ablations' ranking
MANUAL = {"ex11": 2}

# exercise 7 trains the base policy with these exercises' functions
EX7_NEEDS = ("ex1", "ex2", "ex3", "ex4")
# exercise 12, the capstone, runs two rounds of the method with these exercises' functions: the
# method's pieces, and the backward passes and distribution its networks learn with
CAPSTONE_NEEDS = ("ex1", "ex2", "ex3", "ex4", "ex5", "ex6", "ex8", "ex9", "ex10")
# the exercises that take a folder (the notebooks of the exercises they need), not a notebook
BEHAVIOURAL = {"ex7": EX7_NEEDS, "ex12": CAPSTONE_NEEDS}
# the functions their checks take from those notebooks, in order; then the ActionDist of ex2
ARGUMENTS = {"ex7": ["mlp_backward", "gae", "ppo_loss"],
             "ex12": ["mlp_backward", "gae", "ppo_loss", "alter", "select_goal", "relabel",
                      "attention_backward", "join", "expansion_step", "distillation_data",
                      "distillation_tasks"]}
