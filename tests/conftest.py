"""Figures draw off-screen (agent.py pins BLAS to one thread for every test)."""
import matplotlib

matplotlib.use("Agg")
