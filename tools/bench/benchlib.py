"""Helpers shared by the benchmark scripts in tools/bench (standard library only).

Paths, the MPI environment, running octmesh and the p4est reference program,
case lists, the machine description, and plain-text / Markdown tables.
"""

import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OCTMESH = ROOT / "target" / "release" / "octmesh"
P4EST = ROOT / "tools" / "p4est_ref" / "octmesh_p4est"
DATA = ROOT.parent / "shared" / "data"
WORK = ROOT / "target" / "bench"
BUILTIN = ("sphere", "torus")
MIB = 1024.0 * 1024.0
GIB = 1024.0 * MIB


class RunError(Exception):
    pass


def mpi_env():
    env = dict(os.environ)
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    # Only matters on machines with fewer cores than the largest np.
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    # One node, shared memory: Open MPI's default PML selection first probes
    # UCX, which costs about 0.2 s of every start-up on a machine without a
    # network fabric. Every tool run through this environment gets the same.
    env.setdefault("OMPI_MCA_pml", "ob1")
    env["PATH"] = str(Path.home() / ".cargo" / "bin") + os.pathsep + env.get("PATH", "")
    return env


def run(cmd, env):
    p = subprocess.run([str(c) for c in cmd], env=env, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        tail = (p.stderr or p.stdout).strip().splitlines()[-10:]
        raise RunError("command failed (exit %d): %s\n    %s"
                       % (p.returncode, " ".join(map(str, cmd)), "\n    ".join(tail)))
    return p.stdout


def mpirun(np_):
    return ["mpirun", "-np", str(np_)]


def parse_nps(ap, text):
    """Rank counts from '1,2' or '1-4', or an argparse error."""
    out = []
    try:
        for item in text.split(","):
            item = item.strip()
            if not item:
                continue
            lo, sep, hi = item.partition("-")
            out.extend(range(int(lo), int(hi) + 1) if sep else [int(lo)])
    except ValueError:
        ap.error("--np expects integers, e.g. 1,2 or 1-4")
    if not out or min(out) < 1:
        ap.error("--np expects positive integers")
    return out


def parse_cases(text, keep_field=False):
    """Cases from 'sphere:8,bunny:7-9[:outside]': (surface, level[, keep])."""
    cases = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        parts = item.split(":")
        keep = "all"
        if keep_field and len(parts) == 3 and parts[2] in ("all", "inside", "outside"):
            keep = parts.pop()
        if len(parts) != 2 or not parts[0]:
            sys.exit("bad case %r: expected SURFACE:LEVEL or SURFACE:LO-HI%s"
                     % (item, "[:all|inside|outside]" if keep_field else ""))
        lo, sep, hi = parts[1].partition("-")
        if not lo.isdigit() or (sep and not hi.isdigit()):
            sys.exit("bad level in case %r" % item)
        for level in range(int(lo), int(hi if sep else lo) + 1):
            cases.append((parts[0], level, keep) if keep_field else (parts[0], level))
    return cases


def surface_arg(surface):
    """The octmesh argument for a case name, or None if the model is missing."""
    if surface in BUILTIN:
        return surface
    path = Path(surface) if surface.endswith(".stl") else DATA / (surface + ".stl")
    return str(path) if path.is_file() else None


def surface_name(surface):
    return Path(surface).stem if surface.endswith(".stl") else surface


def missing_note(surface):
    return "%s not found" % (surface if surface.endswith(".stl") else DATA / (surface + ".stl"))


def octmesh_stats(np_, args, stats_path, env, mpirun_args=()):
    """Runs `mpirun -np np_ [MPIRUN_ARGS] octmesh ARGS --quiet --stats FILE` and returns the
    stats."""
    run(mpirun(np_) + list(mpirun_args) + [OCTMESH] + list(args)
        + ["--quiet", "--stats", stats_path], env)
    with open(stats_path) as f:
        return json.load(f)


def median(values):
    return statistics.median(values)


def mem_total_bytes():
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def machine_info(env):
    cpu = "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = mem_total_bytes()
    mem = ", %.0f GiB RAM" % (mem / GIB) if mem else ""

    def out(cmd):
        try:
            return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True,
                                  text=True).stdout.strip()
        except OSError:
            return ""

    commit = out(["git", "rev-parse", "--short", "HEAD"]) or "unknown"
    if out(["git", "status", "--porcelain", "--untracked-files=no"]):
        commit += " (with uncommitted changes)"
    mpi = (out(["mpirun", "--version"]).splitlines() or ["unknown"])[0]
    try:
        load = "%.1f" % os.getloadavg()[0]
    except OSError:
        load = "?"
    return {
        "machine": "%d cores (nproc), %s%s, %s %s" % (
            len(os.sched_getaffinity(0)), cpu, mem, platform.system(), platform.release()),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "mpi": mpi,
        "load": load,
    }


def prepare(env, no_build, title, need_p4est=True):
    """Builds the programs (unless no_build), checks they exist, prints the
    title and the machine lines, and returns the machine info."""
    exes = [OCTMESH] + ([P4EST] if need_p4est else [])
    if not no_build:
        # Builds are no-ops when up to date and make sure the measured
        # binaries match the sources.
        try:
            run(["cargo", "build", "--release", "--quiet"], env)
            if need_p4est:
                run(["make", "-s", "-C", str(P4EST.parent)], env)
        except (RunError, OSError) as e:
            sys.exit("build failed: %s" % e)
    for exe in exes:
        if not os.access(exe, os.X_OK):
            sys.exit("missing %s (cargo build --release; make -C tools/p4est_ref)" % exe)
    info = machine_info(env)
    print(title, flush=True)
    print("  machine: %s" % info["machine"])
    print("  date:    %s (load average %s at start)" % (info["date"], info["load"]))
    print("  commit:  %s" % info["commit"])
    print("  mpi:     %s" % info["mpi"], flush=True)
    return info


def start_on_surface(ap, title, need_p4est=False):
    """The start of a tool measuring one surface: adds --no-build to the
    parser `ap` (which has --surface) and parses the command line; returns
    (args, env, surface argument, machine info), or None after printing why
    the surface is skipped."""
    ap.add_argument("--no-build", action="store_true")
    args = ap.parse_args()
    env = mpi_env()
    surface = surface_arg(args.surface)
    if surface is None:
        print("skipped: %s" % missing_note(args.surface))
        return None
    return args, env, surface, prepare(env, args.no_build, title, need_p4est=need_p4est)


def header_line(info, extra=""):
    """One Markdown paragraph naming the machine, date and commit."""
    return ("Machine: %s. Date: %s. Commit: %s. %s. Load average at start: %s.%s"
            % (info["machine"], info["date"], info["commit"], info["mpi"], info["load"],
               " " + extra if extra else ""))


def fmt_s(t):
    if t is None:
        return "-"
    if t < 0.001:
        return "%.6f" % t
    return "%.4f" % t if t < 1 else "%.3f" % t if t < 10 else "%.2f" % t


def fmt_int(n):
    return "-" if n is None else "{:,}".format(n)


def fmt_mib(b):
    return "-" if b is None else "%.0f" % (b / MIB)


def text_table(rows, columns):
    """rows: dicts of strings; columns: (key, header) pairs. First column left-aligned."""
    cells = [[h for _, h in columns]] + [[r.get(k, "") for k, _ in columns] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(columns))]
    lines = []
    for n, c in enumerate(cells):
        lines.append("  ".join(v.ljust(w) if i == 0 else v.rjust(w)
                               for i, (v, w) in enumerate(zip(c, widths))))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(rows, columns, left=("case", "surface", "model", "phase", "agree", "seed")):
    """Columns whose key is in `left` are left-aligned, the others right-aligned."""
    head = [h for _, h in columns]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join(":---" if k in left else "---:" for k, _ in columns) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(r.get(k, "") for k, _ in columns) + " |")
    return "\n".join(lines)


class Progress:
    """Prints rows of a text table as they come, header first."""

    def __init__(self, columns):
        self.columns = columns
        self.rows = []

    def add(self, row):
        self.rows.append(row)
        lines = text_table(self.rows, self.columns).splitlines()
        if len(self.rows) == 1:
            print(lines[0])
            print(lines[1])
        print(lines[-1], flush=True)
