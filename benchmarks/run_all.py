"""Runs every benchmark of the speed and scale targets in turn (make bench): generation, the
estimator's stages, scale, and pose refinement on earth-specular with 0.5 deg + 1 cm of jitter."""
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
RUNS = [
    ("generate_default.py",),
    ("estimator_stages.py",),
    ("scale.py",),
    ("faults.py", "--cases", "pose 0.5 deg + 1 cm", "--losses", "cauchy", "--holdout", "0"),
]
for script, *args in RUNS:
    print(f"== {script} {' '.join(args)}", flush=True)
    subprocess.run([sys.executable, os.path.join(HERE, script), *args], check=True)
