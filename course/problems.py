"""course/problems.py -- the problem set as data: each exercise's notebook, the
functions the student writes in it (in the order its check takes them), and its points (those of its
graded cell; tests/test_exercises.py checks they agree), and the points of the answers graded by
hand."""

NOTEBOOKS = {"ex1": "ex1_mlp_backward.ipynb", "ex2": "ex2_logprob_entropy.ipynb",
             "ex3": "ex3_gae.ipynb", "ex4": "ex4_ppo_loss.ipynb", "ex5": "ex5_alter.ipynb",
             "ex6": "ex6_select_relabel.ipynb", "ex7": "ex7_base_policy.ipynb",
             "ex8": "ex8_attention_backward.ipynb", "ex9": "ex9_expansion_step.ipynb",
             "ex10": "ex10_distillation_data.ipynb", "ex11": "ex11_ablations.ipynb"}
FUNCTIONS = {"ex1": ["mlp_backward"],
             "ex2": ["logp_entropy", "logp_entropy_backward", "log_softmax"],
             "ex3": ["gae"], "ex4": ["ppo_loss"], "ex5": ["alter"],
             "ex6": ["select_goal", "relabel"], "ex8": ["attention_backward"],
             "ex9": ["join", "expansion_step"],
             "ex10": ["distillation_data", "distillation_tasks"],
             "ex11": ["select_goal", "one_drop_away"]}
POINTS = {"ex1": 2, "ex2": 3, "ex3": 2, "ex4": 2, "ex5": 2, "ex6": 2, "ex7": 3, "ex8": 3,
          "ex9": 3, "ex10": 2, "ex11": 2}
# the points of the answers an instructor grades by hand (nbgrader's manually graded cells), on
# top of POINTS: ex11's prediction and explanation of the ablations' ranking
MANUAL = {"ex11": 2}

# exercise 7 trains the base policy with these exercises' functions
EX7_NEEDS = ("ex1", "ex2", "ex3", "ex4")
