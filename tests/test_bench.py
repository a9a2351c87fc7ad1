"""The reproduction report end to end at a tiny budget: bench/reproduce.py runs its variants,
writes RESULTS.md with every table and the targets, and the figures it links to."""
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_reproduce_writes_the_report(tmp_path):
    out, figs = tmp_path / "R.md", tmp_path / "figs"
    subprocess.run([sys.executable, os.path.join(ROOT, "bench", "reproduce.py"), "--seeds", "0",
                    "1", "--features", "plain", "--variants", "ours", "direct-ppo", "no-restrict",
                    "--rounds", "2", "--scale", "0.02", "--root", str(tmp_path / "runs"),
                    "--out", str(out), "--figures", str(figs)], check=True, cwd=tmp_path,
                   capture_output=True)
    text = out.read_text()
    for part in ("### Targets", "### Does equation (1) pick goals", "### Table 1", "### Table 2",
                 "### Direct PPO", "### Table 3", "## Where we differ from the paper"):
        assert part in text, part
    # one row per round of ours, with the paper's round-2 figures next to ours
    assert re.search(r"\| 2 \| .* \| 18 \| .* \| 5\.0 \|", text)
    assert "| round-2 mean over shapes >= 77%" in text
    # the round-0 critic's leading indicator, measured on both seeds' checkpoints and kept
    assert "| feasible among equation (1)'s picks, round-0 critic >= 75% |" in text
    assert (tmp_path / "runs" / "ours-seed1" / "feasible_goals.json").exists()
    assert "after round 1" in text and "w/o restriction" in text
    for name in ("fig1_plain.png", "fig2_plain.png"):
        assert (figs / name).stat().st_size > 1000 and name in text
    assert sorted(os.listdir(tmp_path / "runs")) == sorted(
        [f"{v}-seed{s}{ext}" for v in ("ours", "direct-ppo", "ours-norestrict") for s in (0, 1)
         for ext in ("", ".log")])
