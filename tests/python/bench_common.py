"""What the benchmark scripts share: running a step with its output in a log file."""

import subprocess
import sys


def run(cmd, log):
    """Runs `cmd` with stdout and stderr into `log`; exits with its tail when it fails."""
    with open(log, "w") as f:
        r = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
    if r.returncode != 0:
        with open(log) as f:
            tail = f.read()[-3000:]
        sys.exit(f"{' '.join(map(str, cmd))} failed ({r.returncode}):\n{tail}")
