"""taskexp_lib -- everything of taskexp besides the method (taskexp.py), the world (env2d.py) and
the agent (agent.py): what those three are built from, and the plumbing around them.

  config.py      Config: every hyperparameter of a run, documented, each a command-line flag
  geometry.py    the world's geometry: blocks, table, the x grid, layers, success
  draw.py        pictures of scenes and episodes
  nn.py          the layers, each forward next to its backward; Adam (numpy only)
  features.py    what the networks see of each block
  nets.py        the attention network and the deep set over block tokens
  rollout.py     batched episodes, and the worker processes that run the physics
  shards.py      both cores on one minibatch: data-parallel gradients in two threads
  checkpoint.py  every file a run writes: checkpoints, the resume state, results.json
  shapes.py      the held-out shapes, the families of blocks no goal names, and their scenes
  labels.py      labelled outcomes for V(s, g) (not in the paper)
  orders.py      the generated demonstrations in other orders (not in the paper)
  hindsight.py   a demonstration of goals g is one of any part of g (not in the paper)
  stats.py       what the generated tasks and demonstrations look like
  stress.py      stress actions for the physics tests and benchmarks

and one_blas_thread(), the one setting a run makes for the whole process.
"""
import numpy  # noqa: F401  (loads BLAS first: threadpoolctl limits only libraries already loaded)
from threadpoolctl import threadpool_limits


def one_blas_thread():
    """Pin BLAS to one thread: the networks' matmuls are tiny, so with more threads they run
    10-100x slower, and results change with the thread count. A context manager for a block
    (taskexp.train runs in one); called on its own, for the rest of the program (a notebook)."""
    return threadpool_limits(limits=1)

