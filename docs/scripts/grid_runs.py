"""What the grid scripts share: the 24-target grid (+-4 cm, 2 cm steps)
and one `capsule-mpc simulate` run (paper disturbance, 6 s) read back
from its JSON report."""
import json
import os
import subprocess
import tempfile

NEVER_S = 9.0
STEPS_M = (-0.04, -0.02, 0.0, 0.02, 0.04)
TARGETS = [(a, b) for a in STEPS_M for b in STEPS_M if (a, b) != (0.0, 0.0)]


def simulate(binary, sampling, extra, target, seed):
    """The JSON report of one 6 s run to `target` (two positions, m)."""
    return simulate_args(
        binary,
        ["--target", f"{target[0]},0,{target[1]},0", "--sampling", sampling,
         "--disturbance", "paper", "--seed", str(seed), "--duration", "6"] + extra)


def simulate_args(binary, args):
    """The JSON report of one `capsule-mpc simulate` run with `args`."""
    fd, path = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        subprocess.run([binary, "simulate"] + args + ["--json", path],
                       check=True, capture_output=True)
        with open(path) as f:
            return json.load(f)
    finally:
        os.remove(path)


def pop_option(args, name):
    """The value of `name VALUE` in `args` (removed from it), or None."""
    if name not in args:
        return None
    k = args.index(name)
    value = args[k + 1]
    del args[k:k + 2]
    return value


def draw_arguments(args, flag):
    """`BIN [RUNS] [DRAW_SEED] [--config FILE] [flag]` of the drawn-run
    scripts: (binary, runs, seed, config, capsules, whether `flag` was
    given)."""
    config = pop_option(args, "--config")
    given = flag in args
    if given:
        args.remove(flag)
    binary = args[0]
    runs = int(args[1]) if len(args) > 1 else 400
    seed = int(args[2]) if len(args) > 2 else 1
    capsules = 3 if config and "three" in config else 2
    return binary, runs, seed, config, capsules, given
