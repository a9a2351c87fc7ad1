"""course/dist.py -- the policy distribution built from a student's exercise 2.

agent.ActionDist is the reference solution of exercise 2, so a student kit has it as stubs: there
the distribution that exercise 4's ppo_loss uses and that exercise 7 trains with is the student's
own, made here from their log_softmax, logp_entropy and logp_entropy_backward. Sampling and the
greedy mode are the library's (ActionDist.sample and .mode are not exercised), run on the student's
log_softmax. The same happens in the repository, so a notebook behaves the same in both.
"""
import numpy as np

import agent


class NotDone(NotImplementedError):
    """A student's function that is still a stub, raised where another exercise needs it: the
    message names the exercise."""


def student_action_dist(logp_entropy, logp_entropy_backward, log_softmax, where="exercise 2"):
    """-> a class with agent.ActionDist's interface (log_prob, entropy, backward, sample, mode)
    that runs the student's functions."""

    def mine(fn, *args):
        try:
            return fn(*args)
        except NotImplementedError:
            raise NotDone(f"ActionDist runs your {where}, which is not done yet "
                          f"({fn.__name__} raises NotImplementedError)") from None

    class StudentActionDist(agent.ActionDist):
        def __init__(self, out, n_x):
            out = np.asarray(out, dtype=np.float64)      # as agent.ActionDist: float64 always
            self.out, self.n_x, self.shape = out, n_x, out.shape
            # what ActionDist.sample and .mode read: the heads' log-probabilities
            self.lb = mine(log_softmax, out[..., 0])
            self.lx = mine(log_softmax, out[..., 1:1 + n_x])
            self.ly = mine(log_softmax, out[..., 1 + n_x:])
            self.pb = np.exp(self.lb)

        def log_prob(self, actions):
            return mine(logp_entropy, self.out, np.asarray(actions), self.n_x)[0]

        def entropy(self):
            # H does not depend on the actions: any valid ones will do
            return mine(logp_entropy, self.out, np.zeros((len(self.out), 3), int), self.n_x)[1]

        def backward(self, actions, a, c):
            B = len(self.out)        # the library passes scalars too; the student's takes (B,)
            return mine(logp_entropy_backward, self.out, np.asarray(actions), self.n_x,
                        np.broadcast_to(np.asarray(a, float), (B,)).copy(),
                        np.broadcast_to(np.asarray(c, float), (B,)).copy())

    StudentActionDist.__qualname__ = StudentActionDist.__name__ = "ActionDist"
    return StudentActionDist
