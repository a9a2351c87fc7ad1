"""taskexp_lib/config.py -- every hyperparameter of a run in one documented dataclass (as in
CleanRL).

Each field's docstring says what it is, the section of the paper it belongs to, and why an unusual
value was chosen; taskexp_cli turns every field into a command-line flag with that text as its help.
"""
from dataclasses import dataclass


@dataclass
class Config:
    """Every hyperparameter of a run, with the section of the paper it belongs to. The defaults
    are the laptop run the README reports; `python taskexp.py --help` lists them as flags."""
    seed: int = 0
    """seeds the run's Generator, the networks and the evaluation scenes"""
    rounds: int = 3
    """rounds of task expansion + self-distillation after the base skills (sec 4.2-4.3)"""
    n_blocks: int = 6
    """blocks in the world; the held-out shapes need 6 and the table holds 8"""
    max_steps: int = 10
    """actions per episode before it counts as failed"""
    short_steps: int = 3
    """action budget of the verification run from s_T (sec 4.2) and of the stretch tasks"""
    hidden: int = 128
    """width of the actor's and the critic's per-block networks; the authors' state-based
    settings use 64, which here takes two thirds of the time and learns less (lab/notes.md)"""
    network: str = "attention"
    """sec 3: attention (self-attention over block tokens, as in the paper) | setnet (a deep set:
    blocks see each other only through pooled summaries)"""
    features: str = "plain"
    """sec 3: plain (each block's pose and goal) | relations (plus stacking preconditions
    computed by hand, features.RELATIONS: what the network would otherwise have to learn) |
    relations+leave (plus, for a block in the way, a code of the spot it must leave) |
    relations+leave+stay (plus, for a block that stands under a goal not met yet, that it is a
    support in place)"""
    aux_relations: float = 0.0
    """sec 3, not in the paper: with plain features, the weight of an auxiliary loss by which BC
    and PPO also train the actor's tokens to predict each block's stacking relations
    (features.AUX_FACTS: what hand-computed relations features would give); 0 = off. Training on
    the policy's loss alone takes them out of the tokens (lab/bench/probe.py)"""
    action: str = "drop"
    """sec 3: drop (pick a block and an x; it falls onto whatever lies there, so physics finds
    its height) | place (pick a layer too: a layer the demos never showed is never chosen)"""
    dtype: str = "float32"
    """the networks' arithmetic, float32 | float64: float32 is twice as fast and learns the same
    (the finite-difference tests use float64)"""
    n_envs: int = 32
    """environments stepped in lockstep, one batched policy call per step"""

    base_demos: int = 20000
    """sec 4.1: single-block demonstrations for behaviour cloning"""
    warmup: int = 0
    """sec 4.1: a scene takes warmup + 1 random moves, each a demo if usable, so demos come after
    0..warmup earlier moves and see stacks of every height; the paper's demos come from
    scattered scenes (warmup = 0)"""
    free_table: bool = True
    """sec 4.1: the base demos' "onto the table" moves land on free table spots, as in the
    authors' environment, so that about half of the single-block goals sit on another block
    (off: any x, and in the world that drops 82% of them land on a block: then most one-step
    extensions that a block on the table can carry lie out of the base skills' reach, equation
    (1) picks ones that do not depend on the base task, and the data teach "higher goal first")"""
    base_pairs: int = 0
    """sec 4.1, not in the paper: two-move random demonstrations whose parts (one block's goal
    each; taskexp_lib/hindsight.py) that move a block no goal names join the base demos: a block
    moved away from where the other came to rest, or put under it; 0 = off"""
    clear_pairs: float = 0.0
    """base_pairs: the share of the pairs whose second block goes where the first one stood, so
    that its part shows a site cleared (random pairs mostly show a support built)"""
    max_stay: int = 2
    """sec 4.1: up to this many "stay where you are" goals for other blocks in a base task"""
    bc_epochs: int = 8
    """BC epochs over the base demos (sec 4.1)"""
    distill_epochs: tuple = (8,)
    """sec 4.3: BC epochs over the buffer of generated data in rounds 1, 2, ..., the last value
    for every round after; the policy goes on from the last round's weights. 4 in every round
    took 0.86x the time and cost round 1 eight points of zero-shot success; 8 then 4 cost rounds
    2 and 3 about seven each (lab/notes.md)"""
    bc_batch: int = 256
    """BC minibatch size"""
    bc_lr: float = 1e-3
    """BC Adam learning rate"""

    ppo_steps: int = 20000
    """environment steps per PPO phase (base fine-tuning, self-distillation, direct PPO); the
    paper used ~150M per round on a cluster"""
    ppo_episodes: int = 256
    """episodes per PPO update"""
    stretch: float = 2.0
    """not in the paper: extra episodes per PPO update, as a fraction of ppo_episodes, on
    one-alteration variants of the tasks, so that V(s, g) learns what it cannot reach yet; with
    plain features V must learn from them whether a goal has a support (lab/notes.md)"""
    ppo_epochs: int = 4
    """PPO epochs over each batch"""
    ppo_minibatch: int = 256
    """PPO minibatch size"""
    ppo_lr: float = 3e-4
    """PPO Adam learning rate (actor and critic)"""
    clip: float = 0.2
    """PPO ratio clip epsilon"""
    ent_coef: float = 0.003
    """entropy bonus; small, as BC already spread the policy over sensible actions"""
    vf_coef: float = 0.5
    """value loss weight (with separate networks and Adam, it acts only through the grad clip)"""
    max_grad_norm: float = 0.5
    """global gradient-norm clip per network"""
    gamma: float = 0.9
    """discount; below 1 so that V(s, g) also says how many steps the goal is away"""
    gae_lambda: float = 0.95
    """GAE lambda"""

    expand_episodes: int = 6000
    """sec 4.2: attempts on the previous round's tasks per round; twice the 3000 of 2026-12-05,
    which generated half as many tall tasks and less zero-shot success every round (lab/notes.md)"""
    candidates: int = 64
    """sec 4.2: K, the one-alteration candidates drawn per successful trajectory"""
    p_add: float = 0.5
    """sec 4.2: probability that an alteration adds a goal (else it modifies one)"""
    select: str = "ours"
    """sec 4.2: goal selection, ours (eq. 1) | end2new | init2new (Table 3 ablations)"""
    restrict: bool = True
    """sec 4.2: one alteration; False draws unrelated random tasks (Table 3 "w/o restriction")"""
    other_orders: bool = True
    """sec 4.2, not in the paper: BC learns each generated demonstration's moves in another order
    too, where the simulator, replaying them so from s_0, meets the same goals; the data then
    insist only on the order that physics demands (taskexp_lib/orders.py)"""
    goal_parts: int = 0
    """sec 4.2, not in the paper: parts of its goals drawn per generated demonstration, which BC
    and PPO also learn, each with the moves it needs (replayed without the others), where a block
    that no goal of the part names moves: a support, or a block moved out of the way
    (taskexp_lib/hindsight.py); 0 = off"""
    parts_in: str = "all"
    """goal_parts: all (BC and PPO learn the parts, and the next round extends them) | bc (BC
    alone learns them: PPO's tasks and the next round's come from whole demonstrations)"""

    label_tasks: int = 2000
    """not in the paper: labelled outcomes as data for V(s, g) (taskexp_lib/labels.py), on this
    many tasks, after the base PPO; 0 = off (V learns from PPO alone, as in the paper). The policy
    runs toward one-alteration candidates from s_T and s_0 on the short budget, and V is regressed
    on the discounted outcomes"""
    label_per: int = 4
    """label_tasks: candidates labelled per successful trajectory"""
    label_top: int = 2
    """label_tasks: how many of them are those equation (1) ranks first (where the critic errs,
    its argmax finds it); the rest are drawn at random"""
    label_iters: int = 3
    """label_tasks: rounds of label-then-fit, each on label_tasks / label_iters tasks and all the
    labels so far, so that each labels the picks of the critic the last one left"""
    label_epochs: int = 30
    """label_tasks: epochs of the value regression, split over the label_iters rounds"""
    label_lr: float = 1e-3
    """label_tasks: Adam learning rate of the value regression"""
    label_pair: float = 1.0
    """label_tasks: the weight on the difference V(sT, g) - V(s0, g), the quantity equation (1)
    ranks by, in a second fit on the labelled pairs (agent.pair_value_loss); 0 = no such fit"""

    buffer_size: int = 60000
    """sec 4.3: demo steps, and tasks, kept for self-distillation (oldest dropped): the memory
    bound of a long run"""

    eval_episodes: int = 100
    """sec 5: fixed evaluation scenes per shape, the same after every round"""
    eval_salt: int = 12345
    """sec 5: the evaluation scenes come from the Generator seeded with [seed, eval_salt]"""
    greedy: str = "joint"
    """sec 5: the evaluation's deterministic action: joint (the most likely (block, x) pair) |
    block (the most likely block, then its most likely x: each head's argmax, as the authors'
    code takes it). Evaluation only. A block that must be cleared away can go to many x, so its
    x-probability is spread and the joint rule passes it over for a goal block whose x is sure
    (lab/notes.md, 2026-12-07, issue 53). A checkpoint does not carry it (Agent.load: joint);
    lab/bench/greedy.py tries a checkpoint with both"""
    baseline: str = ""
    """sec 5.3: "direct-ppo" replaces task expansion by PPO on the evaluation tasks"""
    shapes: tuple = ("I", "Y", "3T")
    """sec 5: the held-out shapes evaluated after every round"""
    families: tuple = ("blocked", "air")
    """not in the paper: the task families evaluated after every round beside the shapes, in
    which blocks that no goal names must move (a site to clear, supports to build; shapes.py)"""
    eval_blocks: tuple = (7, 8)
    """not in the paper: worlds of other numbers of blocks in which the held-out shapes are tried
    after every round too, with the weights learnt in this one (none: --eval-blocks alone)"""


# fields that results.json saves as lists
TUPLES = ("shapes", "families", "eval_blocks", "distill_epochs")


class SameAs(str):
    """In ADDED: the field takes the value of the named field of the same run (as a tuple of
    it, for a field of TUPLES)."""


# Fields added since runs were first kept, each with the value that does what the code before it
# did: a run saved without the field resumes with that value
ADDED = {"other_orders": False,                                # 2026-12-04
         "goal_parts": 0, "base_pairs": 0,                       # 2026-12-06
         "clear_pairs": 0.0, "parts_in": "all",                  # 2026-12-07
         "distill_epochs": SameAs("bc_epochs"),                  # 2026-12-07
         "aux_relations": 0.0,                                   # 2026-12-08
         # evaluation only: a run made before learns the same, and is tried on them from its
         # next round on
         "families": ("blocked", "air"),
         "eval_blocks": (7, 8),                                  # 2026-12-06, evaluation only
         "greedy": "joint"}                                      # 2026-12-07, evaluation only
# Fields removed since, each with the only value today's code can go on with: they served variants
# whose findings are in lab/notes.md (hard_picks, label_later_*: measured at main f915fea;
# distill_data: at ba5e9fb; aux_critic: at 23fa0c7)
REMOVED = {"hard_picks": False, "label_later_tasks": 0, "label_later_epochs": None,
           "label_every_round": False, "distill_data": "buffer", "aux_critic": False}


class RemovedSetting(ValueError):
    """A run saved with a setting this version no longer has, at a value it cannot go on with."""


def upgraded(settings):
    """A run's saved settings (a dict) in today's field names, so that runs made by earlier code
    still load and resume: a field of ADDED that the run does not have takes its value there; a
    field of REMOVED is dropped if it holds the value today's code runs (None: any value), and
    refused otherwise (RemovedSetting)."""
    settings = {**ADDED, **settings}
    for name, v in ADDED.items():
        if isinstance(settings[name], SameAs):
            settings[name] = (settings[v],) if name in TUPLES else settings[v]
    for name, value in REMOVED.items():
        if name in settings and value is not None and settings[name] != value:
            raise RemovedSetting(f"made with {name}={settings[name]!r}, a setting this version "
                                 "no longer has (lab/notes.md); go on with main f915fea's code")
        settings.pop(name, None)
    return settings


def saved_config(settings):
    """The Config of a run's settings as results.json saves them (shapes a list, upgraded)."""
    settings = upgraded(settings)
    return Config(**{**settings, **{name: tuple(settings[name]) for name in TUPLES}})
