"""Live cost: ``companion run`` fed a recorded flight in real time over UDP, against replay.

    python bench/live.py [--tlog sitl_fixtures/nominal.tlog] [--duration 60] [--rate 250]
                         [--uniform] [--no-record] [--no-paced] [--no-receive] [--json]
                         [--profile OUT]

The bench is the autopilot. It binds a UDP socket on 127.0.0.1, starts
``companion run --master udpin:127.0.0.1:PORT`` (flight recorder on, into a
temporary folder, as deployed), knocks with a ground station's HEARTBEAT (which
the service ignores) until the service answers, then sends the frames of the
log as recorded, one frame per datagram, and receives on the same socket what
the service sends back. It stops by itself after ``--duration`` seconds of play.

Pacing: by default the log's own timing, scaled so that the mean rate is
``--rate`` messages/s (nominal.tlog averages 104 messages/s, so 250 messages/s
plays the flight 2.4 times faster than it was flown; messages recorded
together, such as HEARTBEAT and SYSTEM_TIME, still leave together).
``--uniform`` sends exactly one message every ``1/rate`` s instead.

Measured, in the same run:

* **CPU** of the service process (its run time, every thread's, from
  ``/proc/PID/task/TID/schedstat``;
  the kernel's share from ``/proc/PID/stat``) over the play (from the first frame
  sent to 1 s after the last), per message and per second of flight played (the
  log time covered);
* **the replay baseline**: ``companion.replay.replay`` of the same frames (the
  played prefix written to a .tlog with their recorded times) in a child process,
  CPU of the ``replay`` call only, per message; the same process's peak RSS;
* **the paced baseline** (``--no-paced`` skips it): in another child process, the
  service's work without its I/O — each frame parsed (``FrameParser``, one frame at
  a time) and handed to a ``Pipeline`` — on the live schedule, sleeping between
  messages; the CPU of that work alone (``time.thread_time``), and of the whole
  process. The replay runs its messages back to back, with every cache warm; a
  process that handles one message every 4 ms finds them cold: on the 2-core
  development machine, idle or loaded, the very same pipeline calls cost 3 to 4
  times more (the ``paced`` column), and batching them would only help at the
  cost of latency. ``live / paced`` is what the live path (event loop, sockets,
  recorder) adds to the same work done at the same pace;
* **the receive floor** (``--no-receive`` skips it): the same play into a child
  process that runs the service's event loop and UDP link and does nothing with what
  it receives (:func:`_child_receive`), measured as the service is. ``receive +
  paced work`` is the floor of the live cost with this loop on this machine, and
  ``live - floor`` what the service adds to it (decoding and the pipeline aside:
  the recorder, the sends, its bookkeeping);
* **peak RSS** of the service (``VmHWM``);
* **latency of a fix to the GPS_INPUT built on it** (below), median and 99th
  percentile;
* that every GPS_INPUT received is the one the replay pipeline makes for the same
  messages (payload byte for byte; the sequence number and CRC aside).

Which GPS_INPUT a fix is in, and the latency
--------------------------------------------
The service publishes when a fix has been fused (``engine.publish_on_fix``), and
otherwise, while no fix is fused, on the autopilot clock (the newest sample time it
has seen, mostly the IMU's); ``GPS_INPUT.time_usec`` is that clock rounded up to the
millisecond, in µs of boot time (``publication_time_s``), and unique (publications
are at least ``min_publish_interval_s`` apart). A GNSS fix arrives
``gnss_latency_s`` (80 ms in the simulated flights) after its validity time, so
matching by time alone would pair a fix with a GPS_INPUT sent before it arrived.

So the bench runs the same frames through a :class:`~companion.pipeline.Pipeline`
(the service's own code, no I/O) and notes, for every GPS_INPUT, the index of the
message that made it (its *trigger*) and its ``time_usec``: a GPS_INPUT received
live is identified by its ``time_usec``. A fix (GPS_RAW_INT) is first included in
the GPS_INPUT of the first trigger at or after it (the fix itself, when it was fused
and the last publication is far enough back). Two latencies are reported, both from
the bench's clock (``time.perf_counter``, the send of a datagram to the receipt of
the GPS_INPUT):

* **fix -> GPS_INPUT**: from sending the fix to receiving the first GPS_INPUT that
  includes it, the figure the acceptance targets (5 ms median, 20 ms at the 99th
  percentile) are for. Published on the tick of ``publish_rate_hz`` instead
  (``publish_on_fix = false``), it holds the wait for the next tick: about 70 ms of
  flight with fixes 80 ms late and ticks every 100 ms (29 ms at 250 messages/s on
  nominal.tlog).
* **service (trigger -> GPS_INPUT)**: from sending the message that made the
  publication to receiving the GPS_INPUT: the time the service itself takes (reading
  the datagram, decoding, the engine, encoding, sending).

The send of a datagram is stamped before ``sendto``: a service woken by it can take
the CPU from the bench inside ``sendto`` and answer before the call returns (stamped
after, a reader thread tried in the service measured a median of 0.02 ms).

What was tried on the receive path, and not kept
------------------------------------------------
Measured on the 2-core development machine (shared, load 4 to 7) at 250
messages/s, in µs of CPU per message, each against a replay of 48 to 65 µs in the
same run (30 s plays, every thread counted):

* a bare receive loop in C (blocking ``recv``): 6 to 8; in Python, blocking
  ``socket.recv`` in the main thread: 16 to 21; the asyncio loop with a datagram
  protocol: 40 to 75 (its ``select`` wake-up, callbacks and handles, cold at
  every datagram); uvloop: 23 to 27;
* a reader thread with a blocking socket handing datagrams to the loop, waking it
  at once for anything but IMU and attitude messages and otherwise after 10 or 20 ms
  (so that the pipeline works on batches): 64 for the bare loop and thread, the
  thread's wake-up and the GIL hand-over costing what the loop's did; the service
  with it 236 and 230 against 234 and 251 without (no gain), fix latency unchanged;
* draining the socket until EAGAIN on each wake-up: at this pace there is one
  datagram to read per wake-up (31 to 46 for the bare loop, no better than the
  protocol);
* uvloop in the service: 227 and 242 against 231, 243 and 241 (within the noise);
* the pipeline itself at the live pace, batched (the paced baseline with the frames
  handed over when a fix arrives or the oldest waiting is W old): 155 (W = 0), 126
  (10 ms), 120 (20 ms), 130 with fixes handed over at once whatever W (a fix comes
  every ~10 messages), against 49 back to back; busy-waiting instead of sleeping
  between messages, 136: the cost is the caches the other processes take meanwhile,
  not the sleep.

The flight recorder already writes into a buffer handed to the OS every
``flush_interval_s`` (or when the buffer is full): 2 % of the service's samples in a
py-spy profile, about 7 µs a message.

Prints a table with the ratios live / replay and live / paced, the floor, the
verdicts, and a progress line on stderr. ``--profile OUT`` attaches ``py-spy record`` to the
service during the play. Linux only (``/proc``). Takes about three times
``--duration`` plus the replay (the paced baseline and the receive floor play as long
as the live run each).
"""

from __future__ import annotations

import argparse
import bisect
import json
import logging
import os
import resource
import select
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

DEFAULT_TLOG = ROOT / "sitl_fixtures" / "nominal.tlog"
START_TIMEOUT_S = 30.0
DRAIN_S = 1.0
"""Receiving goes on this long after the last frame sent (and the CPU window with it)."""
KNOCK_PERIOD_S = 0.2
SERVICE_COMPONENT = 191
TARGET_COST_RATIO = 2.0
TARGET_MEDIAN_MS = 5.0
TARGET_P99_MS = 20.0


# ----------------------------------------------------------------------------- the flight


@dataclass(slots=True)
class Flight:
    """The frames to play, their recorded times and the play schedule."""

    frames: list[bytes]
    log_t_s: list[float]
    offsets_s: list[float]
    """When each frame is sent, from the start of play (s)."""
    flight_s: float
    """Log time covered by the frames played (s)."""
    scale: float
    """Flight seconds per second of play."""


def load_flight(path: Path, duration_s: float, rate_hz: float, uniform: bool) -> Flight:
    """The frames of ``path`` that fit in ``duration_s`` of play at ``rate_hz`` on average."""
    from companion.mavlink.decode import LIGHT_MESSAGE_IDS
    from companion.mavlink.tlog import TlogReader

    reader = TlogReader(path, light_ids=LIGHT_MESSAGE_IDS)  # light: cheaper, same frames
    records = [(t, bytes(msg.get_msgbuf())) for t, msg in reader]
    if len(records) < 2:
        raise SystemExit(f"{path}: fewer than two records")
    t0 = records[0][0]
    log_rate_hz = (len(records) - 1) / (records[-1][0] - t0)
    scale = rate_hz / log_rate_hz
    frames, log_t, offsets = [], [], []
    for k, (t, frame) in enumerate(records):
        offset = k / rate_hz if uniform else (t - t0) / scale
        if offset >= duration_s:
            break
        frames.append(frame)
        log_t.append(t)
        offsets.append(offset)
    flight_s = log_t[-1] - log_t[0]
    if uniform:
        scale = flight_s / offsets[-1] if offsets[-1] > 0 else 1.0
    return Flight(frames, log_t, offsets, flight_s, scale)


def _norm(frame: bytes) -> bytes:
    """A MAVLink 2 frame without its sequence number and CRC (what live and replay share)."""
    return frame[:4] + frame[5:-2]


@dataclass(slots=True)
class Reference:
    """What the pipeline makes of the played messages (the replay's code, in process)."""

    trigger_by_time_us: dict[int, int] = field(default_factory=dict)
    """GPS_INPUT.time_usec -> index of the message that made it."""
    frame_by_time_us: dict[int, bytes] = field(default_factory=dict)
    """GPS_INPUT.time_usec -> its frame, normalised (:func:`_norm`)."""
    triggers: list[int] = field(default_factory=list)
    """Trigger indices, ascending."""
    fixes: list[int] = field(default_factory=list)
    """Indices of the GPS_RAW_INT messages."""


def reference(flight: Flight) -> Reference:
    """Run the frames through a Pipeline as the service parses them (one per datagram)."""
    from companion.config import Config
    from companion.mavlink.decode import LIGHT_MESSAGE_IDS
    from companion.mavlink.framing import FrameParser
    from companion.pipeline import Pipeline

    pipeline = Pipeline(Config())
    parser = FrameParser(light_ids=LIGHT_MESSAGE_IDS)
    out_parser = FrameParser()
    ref = Reference()
    for k, (frame, t_s) in enumerate(zip(flight.frames, flight.log_t_s, strict=True)):
        for msg in parser.feed(frame):
            if msg.get_type() == "GPS_RAW_INT":
                ref.fixes.append(k)
            for out in pipeline.on_message(msg, t_s):
                for out_msg in out_parser.feed(out):
                    if out_msg.get_type() == "GPS_INPUT":
                        ref.trigger_by_time_us[out_msg.time_usec] = k
                        ref.frame_by_time_us[out_msg.time_usec] = _norm(out)
                        if not ref.triggers or ref.triggers[-1] != k:
                            ref.triggers.append(k)
    return ref


# ----------------------------------------------------------------------------- baseline


def _child_replay(tlog: Path) -> None:
    """In a child process: replay ``tlog``, print CPU of the replay call and peak RSS."""
    from companion.replay import replay

    with tempfile.TemporaryDirectory() as tmp:
        cpu0 = time.process_time()
        summary = replay(tlog, Path(tmp) / "out.tlog")
        cpu_s = time.process_time() - cpu0
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(
        json.dumps(
            {
                "cpu_s": cpu_s,
                "messages": summary.messages_in,
                "out": summary.messages_out,
                "flight_s": summary.log_duration_s,
                "peak_rss_mib": peak_kib / 1024.0,
            }
        )
    )


def replay_baseline(flight: Flight, tmp: Path) -> dict[str, float]:
    """``companion.replay.replay`` of the played frames, with their recorded times."""
    from companion.mavlink.tlog import TlogWriter

    path = tmp / "played.tlog"
    with TlogWriter(path) as writer:
        for t_s, frame in zip(flight.log_t_s, flight.frames, strict=True):
            writer.write(t_s, frame)
    return _child_json(["--child-replay", str(path)])


def _child_paced(flight: Flight) -> None:
    """In a child process: parse and handle each frame at its play time, with no I/O."""
    from companion.config import Config
    from companion.mavlink.decode import LIGHT_MESSAGE_IDS
    from companion.mavlink.framing import FrameParser
    from companion.pipeline import Pipeline

    pipeline = Pipeline(Config())
    parser = FrameParser(light_ids=LIGHT_MESSAGE_IDS)
    frames, offsets, log_t = flight.frames, flight.offsets_s, flight.log_t_s
    work_ns = 0
    thread_ns = time.thread_time_ns
    cpu0 = time.process_time()
    start = time.perf_counter() + 0.05
    for k, frame in enumerate(frames):
        delay = start + offsets[k] - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        c0 = thread_ns()
        for msg in parser.feed(frame):
            pipeline.on_message(msg, log_t[k])
        work_ns += thread_ns() - c0
    cpu_s = time.process_time() - cpu0
    print(json.dumps({"work_s": work_ns / 1e9, "cpu_s": cpu_s, "messages": len(frames)}))


def _child_receive(port: int) -> None:
    """In a child process: the receive floor. The service's event loop and UDP link
    (``udpin``, as ``companion run --master udpin:``) receive the played datagrams and
    do nothing with them; the knock is answered, so that the bench can start."""
    import asyncio

    from companion.mavlink.link import open_link

    knock = _gcs_heartbeat()

    async def main() -> None:
        link = await open_link(f"udpin:127.0.0.1:{port}")
        stop = asyncio.Event()
        asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)

        async def receive() -> None:
            while True:
                if await link.recv() == knock:
                    await link.send(knock)

        task = asyncio.create_task(receive())
        await stop.wait()
        task.cancel()
        await link.close()

    asyncio.run(main())


def paced_baseline(args: argparse.Namespace) -> dict[str, float]:
    """The service's work without its I/O, at the live pace, in a child process."""
    return _child_json(
        [
            "--child-paced",
            *("--tlog", str(args.tlog), "--duration", str(args.duration)),
            *("--rate", str(args.rate), *(["--uniform"] if args.uniform else [])),
        ]
    )


def _child_json(args: list[str]) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, __file__, *args],
        check=True,
        stdout=subprocess.PIPE,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


# ----------------------------------------------------------------------------- live


def _proc_cpu_s(pid: int) -> tuple[float, float, float]:
    """(run time, utime, stime) of ``pid`` (s), all its threads together.

    The run time is the scheduler's exact count, summed over the threads
    (``/proc/PID/task/TID/schedstat``, ns; ``/proc/PID/schedstat`` is the main thread's
    alone, blind to a receiving thread); utime and stime (``/proc/PID/stat``, the whole
    process) are sampled at the kernel's tick, too coarse and possibly aliased with a
    4 ms pace for a total, but they tell the kernel's share. A thread that ended
    between two readings is missing from the sum (the service's live as long as it).
    """
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rpartition(")")[2].split()
    ticks = os.sysconf("SC_CLK_TCK")
    user_s, sys_s = int(fields[11]) / ticks, int(fields[12]) / ticks  # stat(5) 14, 15
    try:
        run_ns = 0
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/schedstat") as fh:
                run_ns += int(fh.read().split()[0])
        run_s = run_ns / 1e9
    except (OSError, ValueError, IndexError):
        run_s = user_s + sys_s
    return run_s, user_s, sys_s


def _proc_peak_rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _py_spy() -> str:
    """py-spy: beside this Python (a virtualenv's bin), else on the PATH."""
    beside = Path(sys.executable).parent / "py-spy"
    return str(beside) if beside.exists() else "py-spy"


def _gcs_heartbeat() -> bytes:
    """A ground station's HEARTBEAT (the service ignores it): the knock."""
    from companion.mavlink.dialect import load_dialect

    mod = load_dialect("ardupilotmega")
    mav = mod.MAVLink(None, srcSystem=255, srcComponent=190)
    msg = mod.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)  # MAV_TYPE_GCS, AUTOPILOT_INVALID
    return bytes(msg.pack(mav))


@dataclass(slots=True)
class LiveRun:
    """What the live play measured."""

    sent_at: list[float]
    received: list[tuple[float, bytes]]
    cpu_s: float
    """Run time (schedstat)."""
    ticked_s: float
    """utime + stime, sampled at the tick."""
    sys_s: float
    """stime, sampled at the tick."""
    wall_s: float
    peak_rss_mib: float
    service_stderr: str


def _drain(sock: socket.socket, received: list[tuple[float, bytes]]) -> None:
    while True:
        try:
            data = sock.recv(65536)
        except BlockingIOError:
            return
        received.append((time.perf_counter(), data))


def play_live(
    flight: Flight,
    tmp: Path,
    record: bool,
    progress: bool,
    profile: Path | None = None,
    receive_only: bool = False,
) -> LiveRun:
    """Start the service, play the flight at its schedule, measure, stop the service.

    With ``profile``, ``py-spy record`` samples the service during the play and writes
    a flame graph there (``.svg``; otherwise collapsed stacks, one a line); py-spy must
    be installed, and its sampling costs the service CPU. With ``receive_only``, the
    process played to is :func:`_child_receive` instead of the service.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    config = tmp / "live.toml"
    record_dir = str(tmp / "rec") if record else ""
    config.write_text(f'[link]\nstate_file = "{tmp / "state.json"}"\nrecord_dir = "{record_dir}"\n')
    err_path = tmp / "service.err"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if receive_only:
        command = [sys.executable, __file__, "--child-receive", str(port)]
    else:
        command = [
            *(sys.executable, "-m", "companion", "--log-level", "info", "run"),
            *("--master", f"udpin:127.0.0.1:{port}", "--config", str(config)),
        ]
    with open(err_path, "wb") as err:
        proc = subprocess.Popen(
            command,
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=err,
            env=env,
        )
    dest = ("127.0.0.1", port)
    received: list[tuple[float, bytes]] = []
    sent_at = [0.0] * len(flight.frames)
    try:
        knock = _gcs_heartbeat()
        deadline = time.monotonic() + START_TIMEOUT_S
        while not received:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"service did not answer:\n{err_path.read_text()}")
            sock.sendto(knock, dest)
            if select.select([sock], [], [], KNOCK_PERIOD_S)[0]:
                _drain(sock, received)
        received.clear()
        spy = None
        if profile is not None:
            spy = subprocess.Popen(
                [
                    *(_py_spy(), "record", "--pid", str(proc.pid), "--rate", "250"),
                    *("--format", "flamegraph" if profile.suffix == ".svg" else "raw"),
                    *("-o", str(profile)),
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            time.sleep(1.0)
        frames, offsets = flight.frames, flight.offsets_s
        n = len(frames)
        cpu0 = _proc_cpu_s(proc.pid)
        start = time.perf_counter() + 0.05
        next_progress = start + 1.0
        k = 0
        while k < n:
            now = time.perf_counter()
            due = start + offsets[k]
            if now >= due:
                # stamped before the send: a service woken by the datagram may preempt
                # the bench inside sendto and answer before it returns
                sent_at[k] = time.perf_counter()
                sock.sendto(frames[k], dest)
                k += 1
                continue
            if select.select([sock], [], [], due - now)[0]:
                _drain(sock, received)
            if progress and now >= next_progress:
                next_progress += 1.0
                print(
                    f"\r{'receive' if receive_only else 'live'}: "
                    f"{now - start:5.1f}/{offsets[-1]:.1f} s played, {k} sent, "
                    f"{len(received)} received",
                    end="",
                    file=sys.stderr,
                    flush=True,
                )
        end = time.perf_counter() + DRAIN_S
        while (left := end - time.perf_counter()) > 0:
            if select.select([sock], [], [], left)[0]:
                _drain(sock, received)
        cpu1 = _proc_cpu_s(proc.pid)
        cpu_s = cpu1[0] - cpu0[0]
        ticked_s = cpu1[1] + cpu1[2] - cpu0[1] - cpu0[2]
        sys_s = cpu1[2] - cpu0[2]
        wall_s = time.perf_counter() - start
        peak = _proc_peak_rss_mib(proc.pid)
        if spy is not None:
            spy.send_signal(signal.SIGINT)
            spy.wait(timeout=30)
        if progress:
            print(file=sys.stderr)
    finally:
        sock.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    stderr = err_path.read_text()
    if proc.returncode != 0:
        raise SystemExit(f"service exited with {proc.returncode}:\n{stderr}")
    return LiveRun(sent_at, received, cpu_s, ticked_s, sys_s, wall_s, peak, stderr)


# ----------------------------------------------------------------------------- figures


@dataclass(slots=True)
class Latencies:
    """Latencies in ms, and what could not be matched."""

    fix_ms: list[float]
    service_ms: list[float]
    gps_inputs: int
    identical: int
    unknown: int
    fixes_unanswered: int


def latencies(flight: Flight, ref: Reference, live: LiveRun) -> Latencies:
    """Match the GPS_INPUTs received to their triggers and fixes (module docstring)."""
    from companion.mavlink.framing import FrameParser

    parser = FrameParser()
    arrival_by_time_us: dict[int, float] = {}
    identical = unknown = count = 0
    for t_rx, data in live.received:
        for msg in parser.feed(data):
            if msg.get_type() != "GPS_INPUT" or msg.get_srcComponent() != SERVICE_COMPONENT:
                continue
            count += 1
            time_us = msg.time_usec
            if time_us not in ref.trigger_by_time_us:
                unknown += 1
                continue
            arrival_by_time_us.setdefault(time_us, t_rx)
            identical += _norm(bytes(msg.get_msgbuf())) == ref.frame_by_time_us[time_us]
    arrival_by_trigger = {ref.trigger_by_time_us[t]: a for t, a in arrival_by_time_us.items()}
    service_ms = [(a - live.sent_at[k]) * 1e3 for k, a in arrival_by_trigger.items()]
    fix_ms: list[float] = []
    unanswered = 0
    for fix in ref.fixes:
        j = bisect.bisect_left(ref.triggers, fix)
        if j == len(ref.triggers):
            continue  # no publication after the last fixes played
        arrival = arrival_by_trigger.get(ref.triggers[j])
        if arrival is None:
            unanswered += 1
            continue
        fix_ms.append((arrival - live.sent_at[fix]) * 1e3)
    return Latencies(fix_ms, service_ms, count, identical, unknown, unanswered)


def _pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    if len(values) == 1:
        return values[0]
    return statistics.quantiles(values, n=100, method="inclusive")[int(q) - 1]


def figures(
    flight: Flight,
    base: dict[str, float],
    paced: dict[str, float] | None,
    live: LiveRun,
    lat: Latencies,
    receive: LiveRun | None = None,
) -> dict[str, Any]:
    """Every figure the table shows (``--json`` prints them)."""
    n = len(flight.frames)
    out: dict[str, Any] = {
        "messages": n,
        "flight_s": flight.flight_s,
        "play_s": live.wall_s,
        "speed": flight.scale,
        "live_cpu_us_per_message": live.cpu_s / n * 1e6,
        "live_sys_us_per_message": live.sys_s / n * 1e6,
        "live_ticked_us_per_message": live.ticked_s / n * 1e6,
        "replay_cpu_us_per_message": base["cpu_s"] / base["messages"] * 1e6,
        "live_cpu_s_per_flight_s": live.cpu_s / flight.flight_s,
        "replay_cpu_s_per_flight_s": base["cpu_s"] / base["flight_s"],
        "live_peak_rss_mib": live.peak_rss_mib,
        "replay_peak_rss_mib": base["peak_rss_mib"],
        "fix_latency_ms": {"median": _pct(lat.fix_ms, 50), "p99": _pct(lat.fix_ms, 99)},
        "service_latency_ms": {
            "median": _pct(lat.service_ms, 50),
            "p99": _pct(lat.service_ms, 99),
        },
        "fixes_matched": len(lat.fix_ms),
        "triggers_matched": len(lat.service_ms),
        "gps_inputs": lat.gps_inputs,
        "identical": lat.identical,
        "unknown": lat.unknown,
        "fixes_unanswered": lat.fixes_unanswered,
    }
    if paced is not None:
        out["paced_work_us_per_message"] = paced["work_s"] / paced["messages"] * 1e6
        out["paced_process_us_per_message"] = paced["cpu_s"] / paced["messages"] * 1e6
    if receive is not None:
        out["receive_cpu_us_per_message"] = receive.cpu_s / n * 1e6
    return out


def report(fig: dict[str, Any]) -> str:
    """The table, and the verdicts on the acceptance targets."""
    live_us, base_us = fig["live_cpu_us_per_message"], fig["replay_cpu_us_per_message"]
    paced_us = fig.get("paced_work_us_per_message")
    w = 34

    def row(name: str, live: float, replay: float, fmt: str, paced: float | None = None) -> str:
        paced_s = "" if paced is None else format(paced, fmt)
        return (
            f"{name:<{w}} {live:>10{fmt}} {paced_s:>10} {replay:>10{fmt}} {live / replay:>12.2f}"
            + ("" if paced is None else f" {live / paced:>11.2f}")
        )

    lines = [
        f"flight: {fig['messages']} messages, {fig['flight_s']:.1f} s of flight played in "
        f"{fig['play_s']:.1f} s ({fig['speed']:.2f} x real time; the last {DRAIN_S:g} s "
        "receiving only)",
        f"{'':<{w}} {'live':>10} {'paced':>10} {'replay':>10} {'live/replay':>12}"
        + ("" if paced_us is None else f" {'live/paced':>11}"),
        row("CPU per message, us", live_us, base_us, ".1f", paced_us),
        f"{'  live: utime + stime (ticks)':<{w}} {fig['live_ticked_us_per_message']:>10.1f}",
        f"{'  live: of which stime (ticks)':<{w}} {fig['live_sys_us_per_message']:>10.1f}",
    ]
    if paced_us is not None:
        lines.append(
            f"{'  paced: whole process, with sleeps':<{w}} {'':>10} "
            f"{fig['paced_process_us_per_message']:>10.1f}"
        )
    receive_us = fig.get("receive_cpu_us_per_message")
    if receive_us is not None:
        lines.append(
            f"{'  receive floor (loop + UDP link)':<{w}} {receive_us:>10.1f} {'':>10} "
            f"{'':>10} {receive_us / base_us:>12.2f}"
        )
        if paced_us is not None:
            floor_us = receive_us + paced_us
            lines += [
                f"{'  floor: receive + paced work':<{w}} {floor_us:>10.1f} {'':>10} "
                f"{'':>10} {floor_us / base_us:>12.2f}",
                f"{'  live - floor (the rest)':<{w}} {live_us - floor_us:>10.1f}",
            ]
    lines += [
        row(
            "CPU s per s of flight",
            fig["live_cpu_s_per_flight_s"],
            fig["replay_cpu_s_per_flight_s"],
            ".4f",
        ),
        row("peak RSS, MiB", fig["live_peak_rss_mib"], fig["replay_peak_rss_mib"], ".1f"),
        "",
        f"{'latency, ms':<{w}} {'median':>10} {'p99':>10} {'count':>10}",
        f"{'fix -> GPS_INPUT':<{w}} {fig['fix_latency_ms']['median']:>10.2f} "
        f"{fig['fix_latency_ms']['p99']:>10.2f} {fig['fixes_matched']:>10}",
        f"{'service: trigger -> GPS_INPUT':<{w}} {fig['service_latency_ms']['median']:>10.2f} "
        f"{fig['service_latency_ms']['p99']:>10.2f} {fig['triggers_matched']:>10}",
        "",
        f"GPS_INPUT received {fig['gps_inputs']}, identical to the replay pipeline's "
        f"{fig['identical']}, of unknown time_usec {fig['unknown']}; fixes whose GPS_INPUT "
        f"was not received {fig['fixes_unanswered']}",
    ]
    ratio = live_us / base_us
    lines.append(
        f"live / replay per message = {ratio:.2f} "
        f"({'meets' if ratio <= TARGET_COST_RATIO else 'MISSES'} the {TARGET_COST_RATIO:g} target)"
    )
    for what, key in (("fix -> GPS_INPUT", "fix_latency_ms"), ("service", "service_latency_ms")):
        med, p99 = fig[key]["median"], fig[key]["p99"]
        ok = med <= TARGET_MEDIAN_MS and p99 <= TARGET_P99_MS
        lines.append(
            f"{what} latency median {med:.2f} ms, p99 {p99:.2f} ms ({'meets' if ok else 'MISSES'}"
            f" the {TARGET_MEDIAN_MS:g} / {TARGET_P99_MS:g} ms targets)"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tlog", type=Path, default=DEFAULT_TLOG)
    parser.add_argument("--duration", type=float, default=60.0, help="seconds of play")
    parser.add_argument("--rate", type=float, default=250.0, help="mean messages/s")
    parser.add_argument("--uniform", action="store_true", help="one message every 1/rate s")
    parser.add_argument("--no-record", action="store_true", help="flight recorder off")
    parser.add_argument("--no-paced", action="store_true", help="skip the paced baseline")
    parser.add_argument(
        "--no-receive", action="store_true", help="skip the receive floor (loop + link only)"
    )
    parser.add_argument("--json", action="store_true", help="also print the figures as JSON")
    parser.add_argument(
        "--profile",
        type=Path,
        help="py-spy profile of the service (.svg: flame graph, else collapsed stacks)",
    )
    parser.add_argument("--child-replay", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--child-paced", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--child-receive", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    logging.getLogger("companion").setLevel(logging.ERROR)  # the in-process pipelines' alerts
    if args.child_replay:
        _child_replay(args.child_replay)
        return 0
    if args.child_receive:
        _child_receive(args.child_receive)
        return 0
    if not args.tlog.exists():
        print(f"no such tlog: {args.tlog}", file=sys.stderr)
        return 1
    if args.duration <= 0 or args.rate <= 0:
        print("duration and rate must be > 0", file=sys.stderr)
        return 2
    flight = load_flight(args.tlog, args.duration, args.rate, args.uniform)
    if args.child_paced:
        _child_paced(flight)
        return 0
    print(f"{len(flight.frames)} frames to play; reference pipeline ...", file=sys.stderr)
    ref = reference(flight)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        print("replay baseline ...", file=sys.stderr)
        base = replay_baseline(flight, tmp)
        paced = None
        if not args.no_paced:
            print(f"paced baseline ({flight.offsets_s[-1]:.0f} s) ...", file=sys.stderr)
            paced = paced_baseline(args)
        receive = None
        if not args.no_receive:
            print(f"receive floor ({flight.offsets_s[-1]:.0f} s) ...", file=sys.stderr)
            receive = play_live(flight, tmp, False, True, receive_only=True)
        print("live ...", file=sys.stderr)
        live = play_live(flight, tmp, not args.no_record, True, args.profile)
    fig = figures(flight, base, paced, live, latencies(flight, ref, live), receive)
    print(f"tlog: {args.tlog.name}; flight recorder {'off' if args.no_record else 'on'}")
    print(report(fig))
    if args.json:
        print(json.dumps(fig))
    return 0


if __name__ == "__main__":
    sys.exit(main())
