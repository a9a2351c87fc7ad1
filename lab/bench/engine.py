"""The reproduction's runs on an engine: submitit, on this machine by default or on a SLURM cluster.

    python lab/bench/run_seeds.py --seeds 0 1 2 --variants ours end2new      # here, 2 at a time
    python lab/bench/run_seeds.py --seeds 0 1 2 --variants ours end2new --slurm PARTITION --jobs 6

Each run is one `python -m taskexp_cli` process, independent and resumable (--resume, the same
seed gives the same bytes), so an engine only has to start processes and say how they ended.
Why submitit rather than Ray: most university clusters run SLURM, and submitit submits to it with
nothing to start first (Ray needs a head node and workers running on the cluster), while its local
executor runs the same jobs as processes on this machine. It is pure Python, a few hundred kB with
cloudpickle, and optional: `pip install -e .[cluster]` (the product's install does not have it).
A run that dies is reported with the last lines of its log and the others go on; calling again
reuses the finished runs and resumes the stopped ones. Each job's own output (submitit's logs)
goes to ROOT/.submitit/.
"""
import subprocess
import sys
import time

from tqdm import tqdm

HOURS = 24                      # a job's time limit: the default run takes 10-35 minutes on 2 cores
POLL_S = 2.0                    # how often the jobs are asked whether they have finished


def run_logged(command, log):
    """In the job's process: run command, its output appended to the file log."""
    with open(log, "a") as f:
        subprocess.run(command, check=True, stdout=f, stderr=subprocess.STDOUT)


def executor(folder, slurm=None, cores=1):
    """A submitit executor: local processes, or jobs on the SLURM partition `slurm`."""
    try:
        import cloudpickle
        import submitit
    except ImportError:
        raise SystemExit("the runs go through submitit, an optional dependency: "
                         "pip install -e .[cluster]") from None
    # the jobs unpickle run_logged in a new process, where lab/bench is not on the import path
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    ex = submitit.AutoExecutor(folder=folder, cluster="slurm" if slurm else "local")
    ex.update_parameters(timeout_min=60 * HOURS, cpus_per_task=cores,
                         **({"slurm_partition": slurm} if slurm else {}))
    return ex


def last_lines(path, n=5):
    try:
        with open(path) as f:
            return "".join(f.readlines()[-n:])
    except OSError:
        return "(no log)\n"


def run_all(runs, folder, jobs=2, slurm=None, cores=1, say=tqdm.write):
    """runs: {name: (command, log file)}, each started as one job, at most `jobs` at a time.
    -> {name: the last lines of its log} for the runs that failed (the others go on)."""
    ex = executor(folder, slurm, cores)
    todo, running, failed = list(runs.items()), {}, {}
    with tqdm(total=len(runs), desc="runs", disable=None) as bar:
        try:
            wait(ex, todo, running, failed, jobs, bar, say)
        except KeyboardInterrupt:           # the runs keep what they finished: --resume goes on
            for job, _ in running.values():
                job.cancel(check=False)
            raise SystemExit("interrupted: the same command goes on with the runs "
                             "(finished ones reused, stopped ones resumed)") from None
    return failed


def wait(ex, todo, running, failed, jobs, bar, say):
    """Start jobs while fewer than `jobs` run, until all have ended; a failure is noted."""
    while todo or running:
        while todo and len(running) < jobs:
            name, (command, log) = todo.pop(0)
            running[name] = ex.submit(run_logged, command, log), log
        time.sleep(POLL_S)
        for name, (job, log) in list(running.items()):
            if not job.done():
                continue
            del running[name]
            try:
                job.result()
                say(f"finished {name}")
            except Exception:               # the run's own log says why, not the job's traceback
                failed[name] = last_lines(log)
                say(f"FAILED {name} (log {log}):\n{failed[name]}")
            bar.update(1)
