"""nbgrader configuration of the taskexp exercises (tested with nbgrader 0.9.6).

`python -m course course DIR` copies this file into DIR, the course root, and writes
the assignment next to it. Run every nbgrader command in DIR:

    DIR/nbgrader_config.py           this file
    DIR/source/taskexp/              the assignment: the twelve instructor notebooks (solutions and
                                     nbgrader metadata) and the student kit's library and checks
    nbgrader generate_assignment taskexp
    DIR/release/taskexp/             the student kit, to hand out as it is
    DIR/submitted/STUDENT/taskexp/   each student's folder as handed in (or nbgrader collect)
    nbgrader autograde taskexp       -> DIR/autograded/, scores in DIR/gradebook.db
    nbgrader formgrader              the written answers of exercise 11, graded by hand
    nbgrader export                  -> grades.csv

A notebook is graded in the student's folder after nbgrader copies the files of source/taskexp
that are not notebooks (the library and the checks) over the student's, so a student cannot change
a check. Exercises 7 and 12 read the notebooks of the exercises they run, next to them; nbgrader
grades in name order (hence ex01 ... ex12), so they are there. Loading this file checks that
Python in the grading kernel can import the course: without that, every cell fails on an import
and nbgrader reports 0 points without an error.
"""
import os
import subprocess

c = get_config()  # noqa: F821  (nbgrader defines it when it reads this file)

c.CourseDirectory.course_id = "taskexp"
c.CourseDirectory.root = os.path.dirname(os.path.abspath(__file__))

# Exercise 7 trains a policy (12-21 s on one core here) and exercise 12 runs two rounds of the
# method (about a minute): minutes on a slow or busy machine. nbgrader's default, 30 s per cell,
# would stop them and give them 0 points.
c.Execute.timeout = 600


def kernel_imports_the_course():
    """Stop nbgrader, saying what to install, if the python3 kernel cannot import the course."""
    from jupyter_client.kernelspec import KernelSpecManager

    source = os.path.join(c.CourseDirectory.root, "source", "taskexp")
    if not os.path.isdir(source):
        return
    python = KernelSpecManager().get_kernel_spec("python3").argv[0]
    res = subprocess.run([python, "-B", "-c", "import course"], cwd=source,
                         capture_output=True, text=True)
    if res.returncode != 0:
        last = (res.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise SystemExit(f"nbgrader_config.py: the grading kernel's Python ({python}) cannot "
                         f"import the course in {source}: {last}\n"
                         f"Install its requirements there: {python} -m pip install -r "
                         f"{os.path.join(source, 'requirements.txt')}")


kernel_imports_the_course()
