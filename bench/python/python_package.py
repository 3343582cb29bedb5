"""The Python package's benchmarks, each against a peer measured in the same run.

    python bench/python/python_package.py read [--recording FILE] [--rounds 5] [--out DIR]
    python bench/python/python_package.py live [--seconds 20] [--out DIR]

read: a 60 s recording read into numpy arrays (world, hand, joints, glove, tracker) by
      handblocks.Recording, against the standard Python MCAP reader (`mcap` and `lz4` from
      PyPI) decoding the same fields with numpy, the code a user would write without us. Each
      round runs each reader in a fresh process (wall time, and its peak resident memory less
      an interpreter that imported numpy and the reader), the two interleaved. Without
      --recording, a 60 s recording of config/sessions/live.toml is made first.
live: a running session's `world` read from Python (handblocks.Session.subscribe), beside
      `handblocks hz world`, a Rust reader of the same topic at the same priority, in the same
      session at the same time: each sample's publish -> taken by the reader, and for Python
      also publish -> its numpy views in hand. The session's recorder (a Rust reader at nice
      +10) is listed from the session's report.

Each writes python-read.json / .md / .png or python-live.json / .md / .png under --out
(default out/bench): docs/bench/python.md is made of them. Needs the package (pip install
./python), and for `read` the peer (pip install mcap lz4) and for the plots matplotlib.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
EXE = Path(os.environ.get("HANDBLOCKS_EXE", REPO / "target" / "release" / "handblocks"))
#: Ceilings only a broken pipeline crosses (the tests' own): a bench wants its figures, not the
#: session's verdict on a shared machine.
CEILINGS = ["--set", "budget.origin_to_world_p99_us=20000", "--set", "budget.hop_p99_us=20000"]

# The reader each round runs in its own process: it prints {"seconds", "rows", "checksum"}.
OURS = r"""
import json, sys, time, resource
import numpy as np
import handblocks as hb
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
rec = hb.Recording(sys.argv[1])
w, h, j, g, k = rec.world(), rec.hand(), rec.joints(), rec.glove(), rec.tracker()
seconds = time.perf_counter() - t
rows = {"world": len(w), "hand": len(h), "joints": len(j), "glove": len(g), "tracker": len(k)}
check = float(w.position.sum() + h.finger_points.sum() + j.position.sum() + g.angles.sum()
              + k.wrist_position.sum())
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"seconds": seconds, "rows": rows, "checksum": check,
                  "base_kib": base, "peak_kib": peak}))
"""

# The peer: the standard MCAP reader, decoding our CDR messages with numpy (docs/design.md,
# "Recordings": a 4-byte CDR header, then the sample's bytes; a world's blocks follow its
# header as a CDR sequence).
PEER = r"""
import json, sys, time, resource
import numpy as np
from mcap.reader import make_reader
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
STAMP = [("seq", "<u8"), ("time_ns", "<u8"), ("origin_ns", "<u8"), ("publish_ns", "<u8")]
POSE = [("position", "<f8", 3), ("rotation", "<f8", 4)]
WORLD = np.dtype(STAMP + [("step", "<u8"), ("hand_seq", "<u8"), ("block_count", "<u4"),
                          ("grasped_block", "<i4"), ("finger_count", "<u4"),
                          ("finger_point_count", "<u4", 5),
                          ("finger_points", "<f8", (5, 5, 3))])
BLOCK = np.dtype(POSE + [("mode", "<u4"), ("_r", "<u4")])
HAND = np.dtype(STAMP + [("wrist",) + (np.dtype(POSE),), ("tracked", "<u4"),
                         ("finger_count", "<u4"), ("finger_point_count", "<u4", 5),
                         ("palm_vertex_count", "<u4"), ("finger_points", "<f8", (5, 5, 3)),
                         ("finger_radius", "<f8", 5), ("palm_vertices", "<f8", (16, 3))])
JOINTS = np.dtype(STAMP + [("tracked", "<u4"), ("_r", "<u4"), ("wrist",) + (np.dtype(POSE),),
                           ("joints", np.dtype(POSE), 26)])
GLOVE = np.dtype(STAMP + [("sensor_count", "<u4"), ("_r", "<u4"), ("angles", "<f8", 22)])
TRACKER = np.dtype(STAMP + [("station", "<u4"), ("_r", "<u4"), ("wrist",) + (np.dtype(POSE),)])
DTYPES = {"/hand": HAND, "/joints": JOINTS, "/glove": GLOVE, "/tracker": TRACKER}
t = time.perf_counter()
world, blocks = [], []
rest = {t: [] for t in DTYPES}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages(
            topics=["/world", *DTYPES]):
        body = message.data[4:]
        if channel.topic == "/world":
            head = np.frombuffer(body, WORLD, count=1)
            n = int.from_bytes(body[WORLD.itemsize:WORLD.itemsize + 4], "little")
            at = WORLD.itemsize + 8
            world.append(head)
            blocks.append(np.frombuffer(body, BLOCK, count=n, offset=at))
        else:
            rest[channel.topic].append(np.frombuffer(body, DTYPES[channel.topic], count=1))
each = lambda t: np.concatenate(rest[t]) if rest[t] else np.zeros(0, DTYPES[t])
w = np.concatenate(world)
b = np.stack(blocks)
h, j, g, k = each("/hand"), each("/joints"), each("/glove"), each("/tracker")
# Columns of their own (contiguous), as the arrays handblocks hands back.
position, rotation, mode = b["position"].copy(), b["rotation"].copy(), b["mode"].copy()
fingers, joint_positions = h["finger_points"].copy(), j["joints"]["position"].copy()
angles, wrists = g["angles"].copy(), k["wrist"]["position"].copy()
seconds = time.perf_counter() - t
rows = {"world": len(w), "hand": len(h), "joints": len(j), "glove": len(g), "tracker": len(k)}
check = float(position.sum() + fingers.sum() + joint_positions.sum() + angles.sum()
              + wrists.sum())
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"seconds": seconds, "rows": rows, "checksum": check,
                  "base_kib": base, "peak_kib": peak}))
"""


def say(text: str) -> None:
    print(f"bench python: {text}", file=sys.stderr, flush=True)


def run_reader(code: str, recording: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", code, str(recording)], capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise SystemExit(f"bench python: a reader failed:\n{done.stderr}")
    return json.loads(done.stdout)


def make_recording(seconds: int) -> Path:
    # Beside the build, never under --out (which may be docs/bench).
    path = REPO / "out" / "bench-python" / f"live-{seconds}s.mcap"
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists():
        return path
    say(f"recording {seconds} s of config/sessions/live.toml (renderer off) into {path}")
    # The budget's ceilings as the tests hold them: a recording is wanted here, not a verdict.
    done = subprocess.run([str(EXE), "launch", "config/sessions/live.toml", "--duration",
                           str(seconds), "--set", "renderer.mode=off", *CEILINGS,
                           "--record", str(path), "--force"],
                          cwd=REPO, stdout=subprocess.DEVNULL)
    if done.returncode not in (0, 1) or not path.exists():
        raise SystemExit(f"bench python: the session that records {path} failed")
    return path


def percentiles(us: np.ndarray) -> dict:
    p = np.percentile(us, [50, 90, 99]) if len(us) else [float("nan")] * 3
    return {"count": int(len(us)), "p50": float(p[0]), "p90": float(p[1]), "p99": float(p[2]),
            "max": float(us.max()) if len(us) else float("nan")}


def bench_read(args: argparse.Namespace) -> dict:
    try:
        import mcap  # noqa: F401
        import lz4  # noqa: F401
    except ImportError:
        raise SystemExit("bench python read: the peer is missing: pip install mcap lz4")
    out = Path(args.out)
    recording = Path(args.recording) if args.recording else make_recording(60)
    size = recording.stat().st_size
    rounds = {"handblocks": [], "mcap": []}
    for r in range(args.rounds):
        # Interleaved, the order alternating, so drift on a shared machine hits both.
        order = [("handblocks", OURS), ("mcap", PEER)]
        if r % 2:
            order.reverse()
        for name, code in order:
            rounds[name].append(run_reader(code, recording))
        say(f"round {r + 1}/{args.rounds}: handblocks {rounds['handblocks'][-1]['seconds']:.3f} s, "
            f"mcap {rounds['mcap'][-1]['seconds']:.3f} s")
    ours, peer = rounds["handblocks"], rounds["mcap"]
    assert ours[0]["rows"] == peer[0]["rows"], (ours[0]["rows"], peer[0]["rows"])
    assert np.isclose(ours[0]["checksum"], peer[0]["checksum"], rtol=1e-12, atol=0)
    med = lambda rs, k: float(np.median([x[k] for x in rs]))  # noqa: E731
    extra = lambda rs: float(np.median([(x["peak_kib"] - x["base_kib"]) / 1024 for x in rs]))  # noqa: E731
    result = {
        "recording": str(recording), "bytes": size, "rows": ours[0]["rows"],
        "rounds": args.rounds,
        "handblocks": {"seconds_median": med(ours, "seconds"), "extra_mib_median": extra(ours),
                       "peak_mib_median": med(ours, "peak_kib") / 1024,
                       "seconds": [x["seconds"] for x in ours]},
        "mcap": {"seconds_median": med(peer, "seconds"), "extra_mib_median": extra(peer),
                 "peak_mib_median": med(peer, "peak_kib") / 1024,
                 "seconds": [x["seconds"] for x in peer]},
    }
    result["time_ratio"] = result["handblocks"]["seconds_median"] / result["mcap"]["seconds_median"]
    result["memory_ratio"] = (result["handblocks"]["extra_mib_median"]
                              / result["mcap"]["extra_mib_median"])
    rows = result["rows"]
    md = [
        "# Reading a recording into numpy arrays",
        "",
        f"`{Path(recording).name}`: {size / 1e6:.1f} MB, {rows['world']} worlds, "
        f"{rows['hand']} hands, {rows['glove']} gloves, {rows['tracker']} trackers, "
        f"{rows['joints']} joints samples; each reader in a fresh "
        f"process, {args.rounds} rounds interleaved; medians.",
        "",
        "| reader | time (s) | memory beyond the interpreter (MiB) | peak RSS (MiB) |",
        "|---|---|---|---|",
    ]
    for name, label in (("handblocks", "handblocks.Recording"),
                        ("mcap", "mcap (PyPI) + numpy decoding (the peer)")):
        x = result[name]
        md.append(f"| {label} | {x['seconds_median']:.3f} | {x['extra_mib_median']:.1f} | "
                  f"{x['peak_mib_median']:.1f} |")
    md += ["", f"handblocks / peer: time {result['time_ratio']:.2f}, memory "
           f"{result['memory_ratio']:.2f}. Both read the same rows (checked, with a checksum "
           "of every position read).", ""]
    write(out, "python-read", result, md, lambda ax: plot_read(ax, result))
    return result


def plot_read(axes, result: dict) -> None:
    names = ["handblocks", "mcap"]
    axes[0].bar(names, [result[n]["seconds_median"] for n in names], color=["C0", "C7"])
    for n in names:
        axes[0].scatter([n] * len(result[n]["seconds"]), result[n]["seconds"], color="k", s=8,
                        zorder=3)
    axes[0].set_ylabel("seconds to arrays (median; dots: rounds)")
    axes[1].bar(names, [result[n]["extra_mib_median"] for n in names], color=["C0", "C7"])
    axes[1].set_ylabel("MiB beyond the interpreter")
    axes[0].set_title("read a 60 s recording")
    axes[1].set_title("peak memory")


def live_round(args: argparse.Namespace, k: int, hz_first: bool) -> dict:
    """One session: Python and `handblocks hz world` read its world at once; `hz_first`: the
    Rust reader attaches first (a notification wakes the listeners in the order they came,
    so each order is measured)."""
    import handblocks as hb

    bus = f"pybench{os.getpid()}r{k}"
    report = Path(tempfile.mkdtemp()) / "report.json"
    rec = report.with_name("live.mcap")
    session = subprocess.Popen(
        [str(EXE), "launch", "config/sessions/live.toml", "--bus-id", bus,
         "--duration", str(args.seconds + 6), "--set", "renderer.mode=off", *CEILINGS,
         "--record", str(rec), "--report", str(report), "--force"],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    while True:
        try:
            s = hb.Session(bus)
            break
        except hb.SessionError:
            if time.monotonic() > deadline or session.poll() is not None:
                raise
            time.sleep(0.02)
    while s.topics()["world"]["publishers"] == 0:
        time.sleep(0.01)
    hz = lambda: subprocess.Popen(  # noqa: E731
        [str(EXE), "hz", "world", "--session", bus, "--seconds", str(args.seconds)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if hz_first:
        before = s.topics()["world"]["subscribers"]
        rust = hz()
        while s.topics()["world"]["subscribers"] == before:
            time.sleep(0.005)
        worlds = s.subscribe("world")
    else:
        worlds = s.subscribe("world")
        rust = hz()
    say(f"round {k + 1}: reading world for {args.seconds} s beside `handblocks hz world` "
        f"({'it' if hz_first else 'Python'} attached first)")
    taken, in_hand = [], []
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        w = worlds.receive(timeout=0.5)
        if w is None:
            continue
        fields = w.fields()
        views = hb.monotonic_ns()
        taken.append(w.received_ns - w.publish_ns)
        in_hand.append(views - w.publish_ns)
        del fields, w
    received, missed = worlds.counts()
    _, hz_err = rust.communicate(timeout=60)
    del worlds, s
    session.wait(timeout=120)
    line = [x for x in hz_err.splitlines() if "publish -> taken here" in x]
    if not line:
        raise SystemExit(f"bench python live: hz said no latency:\n{hz_err}")
    vals = {k: float(v) for k, v in
            [p.strip().split(" ")[:2]
             for p in line[-1].split(":", 2)[2].replace(" us", "").split(",")]}
    recorder = json.loads(report.read_text())["stages"]["recorder"]["hop_us"]
    return {
        "hz_first": hz_first, "received": received, "missed": missed,
        "python_taken_us": percentiles(np.array(taken) / 1e3),
        "python_views_us": percentiles(np.array(in_hand) / 1e3),
        "rust_hz_taken_us": {"p50": vals["p50"], "p90": vals["p90"], "p99": vals["p99"],
                             "max": vals["max"]},
        "recorder_hop_us": {k: recorder[k] for k in ("count", "p50", "p99") if k in recorder},
    }


def bench_live(args: argparse.Namespace) -> dict:
    out = Path(args.out)
    rounds = [live_round(args, k, hz_first=bool(k % 2)) for k in range(args.rounds)]
    keys = ["python_taken_us", "python_views_us", "rust_hz_taken_us", "recorder_hop_us"]
    med = {k: {q: float(np.median([r[k][q] for r in rounds])) for q in rounds[0][k]
               if q != "count"} for k in keys}
    result = {"seconds": args.seconds, "rounds": rounds, **med,
              "received": sum(r["received"] for r in rounds),
              "missed": sum(r["missed"] for r in rounds)}
    result["p50_ratio"] = result["python_taken_us"]["p50"] / result["rust_hz_taken_us"]["p50"]
    result["p99_ratio"] = result["python_taken_us"]["p99"] / result["rust_hz_taken_us"]["p99"]
    received, missed = result["received"], result["missed"]
    md = [
        "# Reading a live session from Python",
        "",
        f"`config/sessions/live.toml` (renderer off, recording), its `world` read for "
        f"{args.seconds} s by Python and by `handblocks hz world` at once: publish -> taken by "
        f"the reader (both time it as they take the sample, before copying anything). "
        f"{args.rounds} sessions, the two readers attaching in turn first (a notification "
        f"wakes listeners in the order they came); medians of the rounds' percentiles. Python "
        f"received {received} samples, missed {missed}.",
        "",
        "| reader | p50 (us) | p90 (us) | p99 (us) | max (us) |",
        "|---|---|---|---|---|",
    ]
    def row(label, x):
        cell = lambda q: f"{x[q]:.1f}" if q in x else "-"  # noqa: E731
        md.append(f"| {label} | {cell('p50')} | {cell('p90')} | {cell('p99')} | {cell('max')} |")
    row("Python `Session.subscribe` (taken)", result["python_taken_us"])
    row("Python, numpy views in hand", result["python_views_us"])
    row("Rust `handblocks hz world` (the peer)", result["rust_hz_taken_us"])
    row("Rust recorder (nice +10, every topic; its report)", result["recorder_hop_us"])
    md += ["", f"Python / Rust peer: p50 {result['p50_ratio']:.2f}, p99 "
           f"{result['p99_ratio']:.2f}.", ""]
    write(out, "python-live", result, md, lambda ax: plot_live(ax, result))
    return result


def plot_live(axes, result: dict) -> None:
    labels = ["python taken", "python views", "rust hz", "recorder"]
    keys = ["python_taken_us", "python_views_us", "rust_hz_taken_us", "recorder_hop_us"]
    for ax, q in zip(axes, ["p50", "p99"]):
        ax.bar(labels, [result[k][q] for k in keys], color=["C0", "C1", "C7", "C2"])
        ax.set_ylabel(f"{q}, us")
        ax.set_title(f"world: publish -> taken, {q}")
        ax.tick_params(axis="x", labelrotation=20)


def provenance(command: str) -> list:
    """Where a page's figures come from: the command, when, the commit, the machine."""
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                capture_output=True, text=True).stdout.strip() or "?"
    except OSError:
        commit = "?"
    cpu = "?"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return [
        f"- command: `{command}`",
        f"- when: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}",
        f"- commit: {commit}",
        f"- machine: {cpu}, {len(os.sched_getaffinity(0))} CPUs available to the run",
        "",
    ]


def write(out: Path, name: str, result: dict, md: list, plot) -> None:
    out.mkdir(parents=True, exist_ok=True)
    command = "python bench/python/python_package.py " + " ".join(sys.argv[1:])
    md = md[:2] + provenance(command) + [f"![{md[0][2:]}]({name}.png)", ""] + md[2:]
    (out / f"{name}.json").write_text(json.dumps(result, indent=2) + "\n")
    (out / f"{name}.md").write_text("\n".join(md))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), dpi=100)
        plot(axes)
        fig.tight_layout()
        fig.savefig(out / f"{name}.png")
        say(f"wrote {out / name}.json, .md and .png")
    except ImportError:
        say(f"wrote {out / name}.json and .md (no plot: pip install matplotlib)")
    print("\n".join(md))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    read = sub.add_parser("read", help="a 60 s recording into arrays, against the mcap reader")
    read.add_argument("--recording", help="a recording (default: make a 60 s one)")
    read.add_argument("--rounds", type=int, default=5)
    read.add_argument("--out", default="out/bench")
    live = sub.add_parser("live", help="a live session's world read from Python and from Rust")
    live.add_argument("--seconds", type=int, default=15)
    live.add_argument("--rounds", type=int, default=4)
    live.add_argument("--out", default="out/bench")
    args = parser.parse_args()
    if not EXE.exists():
        raise SystemExit(f"bench python: {EXE} is missing: cargo build --release")
    (bench_read if args.what == "read" else bench_live)(args)


if __name__ == "__main__":
    main()
