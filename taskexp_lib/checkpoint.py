"""taskexp_lib/checkpoint.py -- the files a run is resumed from, loaded from or compared by: agent
checkpoints (round{k}.npz), the resume state (state.npz) and results.json.

Plain .npz files, never pickle. Every write is atomic (a temporary file, then a rename), so a run
killed mid-write leaves the previous file intact, and byte-identical for identical arrays, so two
runs can be compared file by file (lab/bench/compare_runs.py). A checkpoint carries the
configuration it needs to be loaded (sizes, dtype, network, features, the world's geometry), and
loading checks each of them, naming the file and the mismatch.
"""
import json
import os
import zipfile
from dataclasses import asdict

import numpy as np

from .config import TUPLES, RemovedSetting, saved_config, upgraded
from .features import FEATURES
from .geometry import GEOMETRY
from .nets import NETWORKS

# 2: the header records the world's GEOMETRY; 3: its features; 4: the features code no layers
FORMAT_VERSION = 4
STATE_VERSION = 1
STATE_KEYS = ("state_version", "round", "results", "run_rng", "buffer_obs", "buffer_act",
              "all_tasks.states", "all_tasks.goals", "prev_tasks.states", "prev_tasks.goals")


# ---- Atomic files ---------------------------------------------------------------------------

def atomic_write(path, write):
    """Call write(tmp) to fill a temporary file next to `path`, then rename it to `path`."""
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def save_npz(path, arrays):
    """Write {name: array} as a plain .npz (no pickle), atomically; fixed zip timestamps and
    sorted keys make it byte-identical for identical arrays."""
    def write(tmp):
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as zf:
            for key in sorted(arrays):
                info = zipfile.ZipInfo(key + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
                with zf.open(info, "w", force_zip64=True) as fh:
                    np.lib.format.write_array(fh, np.asarray(arrays[key]), allow_pickle=False)
    atomic_write(path, write)


def load_npz(path):
    """Read a .npz without pickle -> {name: array}; ValueError naming the file if unreadable."""
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):       # a bare .npy array, not named arrays
            raise ValueError("a single array")
        with z:
            return {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
        # numpy's own message for a file that is no zip suggests allow_pickle: never do that here
        why = "not a zip of arrays" if "pickle" in str(e) else f"{type(e).__name__}: {e}"
        raise ValueError(f"{path}: not a readable .npz file, so not a checkpoint ({why})") from e


def save_json(path, obj):
    """Write JSON atomically, like save_npz."""
    def write(tmp):
        with open(tmp, "w") as f:
            json.dump(obj, f, indent=1)
    atomic_write(path, write)


# ---- Agent checkpoints: round{k}.npz --------------------------------------------------------

def header(agent):
    """What load_agent needs to rebuild `agent`: its sizes, dtype, network, features and the
    world's geometry that the features assume, and, if it has one, its auxiliary loss's weight
    (written only then, so that the files of agents without one keep their bytes)."""
    out = {"format_version": np.array(FORMAT_VERSION, dtype=np.int64),
           "sizes": np.array([agent.n_blocks, agent.n_x, agent.n_y, agent.hidden], dtype=np.int64),
           "dtype": np.array(agent.dtype.name),
           "network": np.array(agent.network),
           "features": np.array(agent.feature_set),
           "geometry": np.array(list(GEOMETRY.values()), dtype=np.float64)}
    if agent.aux > 0:
        out["aux"] = np.array(agent.aux, dtype=np.float64)
    return out


def save_agent(agent, path, extra=None):
    """The header, every parameter and any `extra` arrays as a plain .npz (save_npz)."""
    save_npz(path, {**header(agent), **agent.state_dict(), **(extra or {})})


def _check_header(data, path):
    """The header of checkpoint `data` (read from `path`) -> (sizes, dtype, network, features,
    aux), or ValueError naming the file and the mismatch."""
    if "format_version" not in data or "sizes" not in data:
        raise ValueError(f"{path}: not an agent checkpoint (no format_version and sizes)")
    version, sizes = data["format_version"], data["sizes"]
    if version.shape != () or version.dtype.kind not in "iu" or int(version) != FORMAT_VERSION:
        raise ValueError(f"{path}: format_version {version}, expected {FORMAT_VERSION}")
    if sizes.shape != (4,) or sizes.dtype.kind not in "iu" or (sizes < 1).any():
        raise ValueError(f"{path}: sizes {sizes}, expected 4 positive ints "
                         "(n_blocks, n_x, n_y, hidden)")
    geometry = data.get("geometry", np.zeros(0))
    if geometry.shape != (len(GEOMETRY),) or (geometry != list(GEOMETRY.values())).any():
        saved = dict(zip(GEOMETRY, geometry.tolist()))
        diff = {k: (saved.get(k), v) for k, v in GEOMETRY.items() if saved.get(k) != v}
        raise ValueError(f"{path}: made for a world of other geometry than env2d's "
                         f"(saved, now): {diff}")
    dtype = str(data.get("dtype", ""))
    if dtype not in ("float32", "float64"):
        raise ValueError(f"{path}: dtype {dtype!r}, expected float32 or float64")
    network = str(data.get("network", ""))
    if network not in NETWORKS:
        raise ValueError(f"{path}: network {network!r}, expected one of {sorted(NETWORKS)}")
    features = str(data.get("features", ""))
    if features not in FEATURES:
        raise ValueError(f"{path}: features {features!r}, expected one of {FEATURES}")
    aux = data.get("aux", np.array(0.0))                # absent: made without an auxiliary loss
    if "aux" in data and (aux.shape != () or aux.dtype.kind != "f" or not aux > 0):
        raise ValueError(f"{path}: aux {aux}, expected the auxiliary loss's weight, above 0")
    return [int(k) for k in sizes], dtype, network, features, float(aux)


def load_agent(cls, path, extra=()):
    """Read a file written by save_agent -> an agent of class `cls` (agent.Agent), or (agent,
    {key: array}) for the keys in `extra`. ValueError naming the file on a corrupt or truncated
    file, a wrong format version, a world of another geometry, or keys or shapes that do not match
    the sizes."""
    data = load_npz(path)
    if "state_version" in data and "state_version" not in extra:
        raise ValueError(f"{path}: a run's resume state, not an agent checkpoint; load one of "
                         "the run's round{k}.npz files")
    sizes, dtype, network, features, aux = _check_header(data, path)
    agent = cls(*sizes, dtype=dtype, network=network, features=features, aux=aux)
    params, extra = agent.state_dict(), set(extra)
    missing = extra - set(data)
    if missing:
        raise ValueError(f"{path}: missing {sorted(missing)}")
    stored = set(data) - set(header(agent)) - extra
    if set(params) != stored:
        raise ValueError(f"{path}: keys do not match sizes {sizes}: "
                         f"{sorted(set(params) ^ stored)}")
    for k, p in params.items():
        have = data[k]
        if have.shape != p.shape or have.dtype != p.dtype or not np.isfinite(have).all():
            # a first layer of another width: the feature set has changed since it was saved
            width = agent.features(np.zeros((1, agent.n_blocks, 6))).shape[-1]
            other = have.ndim == 2 and p.shape[0] == width and have.shape[1:] == p.shape[1:]
            why = (f": its networks read {have.shape[0]} feature columns, the {features!r} "
                   f"features have {width} today (code of another day made it)" if other else "")
            raise ValueError(f"{path}: {k} is {data[k].dtype} {data[k].shape}, expected finite "
                             f"{p.dtype} {p.shape} for sizes {sizes}{why}")
        p[...] = data[k]                      # in place: the networks and Adam share p
    return (agent, {k: data[k] for k in extra}) if extra else agent


# ---- The resume state: state.npz ------------------------------------------------------------

def training_state(agent):
    """What decides the agent's future updates besides its parameters, for resuming a run
    exactly: both Adam states (m, v, t) and the agent's own Generator (its state as JSON text)."""
    out = {"rng": np.array(json.dumps(agent.rng.bit_generator.state))}
    for name in ("actor_opt", "critic_opt"):
        opt = getattr(agent, name)
        out[f"{name}.t"] = np.array(opt.t, dtype=np.int64)
        out.update({f"{name}.{mv}.{k}": a for mv in "mv" for k, a in getattr(opt, mv).items()})
    return out


def load_training_state(agent, data, path):
    """Inverse of training_state, from the arrays `data` of file `path` (named in errors)."""
    for key, want in training_state(agent).items():
        have = data.get(key)
        if have is None or have.shape != want.shape or have.dtype.kind != want.dtype.kind:
            raise ValueError(f"{path}: {key} missing or not like {want.dtype} {want.shape}")
    agent.rng.bit_generator.state = json.loads(str(data["rng"]))
    for name in ("actor_opt", "critic_opt"):
        opt = getattr(agent, name)
        opt.t = int(data[f"{name}.t"])
        for mv in "mv":
            getattr(opt, mv).update({k: data[f"{name}.{mv}.{k}"].copy() for k in opt.params})


def tasks_to_arrays(tasks, n_blocks):
    """[(s0 (n, 6), {block: (x, y)})] -> states (N, n, 6), goals (N, n, 3) of x, y and the goal's
    place in the dict (nan: no goal). The order matters: alter() draws from list(goals)."""
    states = np.stack([s0 for s0, _ in tasks])
    goals = np.full((len(tasks), n_blocks, 3), np.nan)
    for i, (_, g) in enumerate(tasks):
        for order, (b, (x, y)) in enumerate(g.items()):
            goals[i, b] = (x, y, order)
    return states, goals


def arrays_to_tasks(states, goals):
    """Inverse of tasks_to_arrays."""
    out = []
    for s0, g in zip(states, goals):
        blocks = sorted(np.flatnonzero(~np.isnan(g[:, 2])), key=lambda b: g[b, 2])
        out.append((s0, {int(b): (float(g[b, 0]), float(g[b, 1])) for b in blocks}))
    return out


def save_state(path, agent, run, rng):
    """After a round: the agent with its optimiser, the run's Generator, the RunState `run`."""
    arrays = {"state_version": np.array(STATE_VERSION), "round": np.array(run.last_round),
              "results": np.array(json.dumps(run.results)),
              "run_rng": np.array(json.dumps(rng.bit_generator.state)),
              "buffer_obs": run.buffer_obs, "buffer_act": run.buffer_act, **training_state(agent)}
    for name in ("all_tasks", "prev_tasks"):
        arrays[f"{name}.states"], arrays[f"{name}.goals"] = tasks_to_arrays(getattr(run, name),
                                                                            agent.n_blocks)
    save_agent(agent, path, extra=arrays)


def load_state(path, cfg, rng, template):
    """Read what save_state wrote for a run with settings cfg, whose fresh agent is `template`;
    restore rng -> (agent, the RunState's fields as a dict). ValueError naming the file when it
    is unreadable or from other settings."""
    extra = STATE_KEYS + tuple(training_state(template))
    saved, data = load_agent(type(template), path, extra=extra)
    if int(data["state_version"]) != STATE_VERSION:
        raise ValueError(f"{path}: state_version {data['state_version']}, expected {STATE_VERSION}")
    results = json.loads(str(data["results"]))
    ours, theirs = asdict(cfg), upgraded(results["config"])
    theirs["rounds"] = ours["rounds"]                                        # rounds may grow
    for name in TUPLES:                                         # lists in JSON, ADDED's tuples
        ours[name], theirs[name] = list(ours[name]), list(theirs[name])
    if ours != theirs:
        diff = {k: (theirs.get(k), v) for k, v in ours.items() if theirs.get(k) != v}
        raise ValueError(f"{path}: saved by a run with other settings (saved, now): {diff}")
    results["config"] = asdict(cfg)
    load_training_state(saved, data, path)
    rng.bit_generator.state = json.loads(str(data["run_rng"]))
    run = dict(last_round=int(data["round"]), buffer_obs=data["buffer_obs"],
               buffer_act=data["buffer_act"], results=results)
    for name in ("all_tasks", "prev_tasks"):
        run[name] = arrays_to_tasks(data[f"{name}.states"], data[f"{name}.goals"])
    return saved, run


def saved_results(out):
    """(results of the run in directory `out`, None), or (None, why not). results.json is read
    first; if it is damaged, the copy inside state.npz (written just before it) serves."""
    why = []
    for name in ("results.json", "state.npz"):
        path = os.path.join(out, name)
        try:
            if name == "results.json":
                with open(path) as f:
                    results = json.load(f)
            else:
                with np.load(path, allow_pickle=False) as z:
                    results = json.loads(str(z["results"]))
            results["rounds"][-1]["round"]           # a KeyError or IndexError: no round done
            saved_config(results["config"])          # a TypeError: not settings of this code
            return results, None
        except FileNotFoundError:
            why.append(f"no {name}")
        except RemovedSetting as e:                   # readable, but not by this version
            return None, str(e)
        except (OSError, ValueError, KeyError, TypeError, IndexError, AttributeError, EOFError,
                zipfile.BadZipFile) as e:
            why.append(f"{name} unreadable: {type(e).__name__}")
    return None, " and ".join(why)
