"""``humanpt bench [runtime|alter|rsi|ur|render|perception|faults]``: print the tables of what
``humanpt.bench`` measures.  Nothing here is asserted."""

from __future__ import annotations

import sys

from humanpt.runtime import tables


def bench_runtime(args) -> int:
    from humanpt.bench.measure import measure_runtime

    print("humanpt bench runtime (loopback, router and both clients in one process; medians of noisy "
          "shared machines: compare ratios)", flush=True)
    trips, writes = measure_runtime(args.n, args.seconds, progress=lambda label: print(f"  measured {label}",
                                                                                           flush=True))
    rows = []
    for t in trips:
        if t.n == 0:
            rows.append((f"round trip, {t.label}", "no replies", "", ""))
        else:
            rows.append((f"round trip, {t.label}", f"{t.p50_ms:.3f} ms", f"{t.p99_ms:.3f} ms", f"n={t.n}"))
    for w in writes:
        notes = [f"file/payload {w.file_over_payload:.2f}"] if w.file_over_payload is not None else []
        if w.baseline_mb_s:
            notes.append(f"{w.mb_s / w.baseline_mb_s:.2f}x the raw mcap Writer ({w.baseline_mb_s:.1f} MB/s)")
        rows.append((f"MCAP write, {w.label}", f"{w.mb_s:.1f} MB/s", f"{w.msg_s:.0f} msg/s", "; ".join(notes)))
    print("\n" + tables.render(["case", "p50 / rate", "p99 / msgs", "note"], rows, align="lrrl"))
    return 0


def bench_render(args) -> int:
    """Frames per second of the simulated PSVS camera at its default settings."""
    from humanpt.bench.measure import measure_render

    b = measure_render(args.frames)
    n = b.frames
    print(f"humanpt bench render: {b.width_px}x{b.height_px}, 3 sources x 2 views at "
          f"600 mm, blur {b.blur_sigma_px} px, shot + read noise; {n} frames per case")
    rows = [["render (renderer alone)", f"{1 / b.render_s:.0f}", f"{1e3 * b.render_s:.3f}"],
            *(["  " + name, "", f"{1e3 * t:.3f}"] for name, t in b.stages_s.items()),
            ["sim_camera core step (+ message)", f"{1 / b.core_step_s:.0f}", f"{1e3 * b.core_step_s:.3f}"]]
    print("\n" + tables.render(["case", "frames/s", "ms/frame"], rows))
    return 0


def bench_perception(args) -> int:
    """Images per second of each perception method and of its baselines (a naive OpenCV
    pipeline, one read of the frame), measured interleaved in this process at 640x480 and
    1920x1200, on one core; and (unless ``--no-accuracy``) both methods' accuracy on twin
    images with ground truth."""
    from humanpt.bench.measure import FLOOR, measure_perception, perception_accuracy, pin_one_cpu
    from humanpt.testing.perception_eval import format_table

    pinned = pin_one_cpu()
    n = max(1, args.images)
    rows = measure_perception(n)
    print(f"humanpt bench perception: twin image sequences (a target moving 0.4 mm, 0.1 deg per image "
          f"at ~600 mm, default noise; 1920x1200: the same optics on a larger sensor), {n} images per case, "
          f"cases interleaved in 8 rounds, cv2 threads 1{pinned}")
    floor = {r.size: r for r in rows if r.case == FLOOR}
    cells = []
    for r in rows:
        ratio = "" if r.ratio is None else f"{r.ratio:.2f}x {'whole image' if r.case.startswith('tracking') else 'naive'}"
        of_floor = f"{100.0 * floor[r.size].cpu_ms / r.cpu_ms:.1f} %" if r.size in floor else ""
        cells.append([r.size, r.method, r.case, f"{r.rate:.0f}", f"{r.cpu_ms:.3f}", f"{r.p50_ms:.3f}",
                      f"{r.p99_ms:.3f}", ratio, of_floor])
    print("\n" + tables.render(["size", "method", "case", "images/s", "CPU ms", "wall p50 ms", "wall p99 ms",
                                "ratio", "floor / it"], cells, align="lllrrrrrr"))
    track = {r.size: r for r in rows if r.method == "weighted" and r.case.startswith("tracking")}
    if len(track) == 2:
        small, large = track.values()
        print(f"\ntracking {large.size} / {small.size}: {large.rate / small.rate:.2f} (images/s)")
    print("images/s and CPU ms: the median CPU time of this thread per image (what the work costs; the wall "
          "times also hold what other processes took); ratio = the baseline's median CPU time / the case's "
          "(> 1: faster than the baseline); floor / it = the memory floor's / the case's.")
    if not args.no_accuracy:
        print(f"\naccuracy on twin images with ground truth ({args.accuracy_images} per set, seed {args.seed}; "
              "bound: geometry error model at the measured centre RMS):\n")
        print(format_table(perception_accuracy(args.accuracy_images, args.seed)))
    return 0


def bench_alter(args) -> int:
    """robot_gateway <-> sim_robot over a real pty (see ``humanpt.bench.alter``)."""
    from humanpt.bench.alter import line_capacity, measure_alter, shortest_sustained
    from humanpt.sim_robot.rsi import LATENCY_EDGES_MS

    periods = tuple(float(p) for p in args.periods.split(",") if p.strip())
    mode = "zenoh" if args.zenoh else "threads"
    print(f"humanpt bench alter ({mode}: gateway <-> sim_robot over a real pty; a pty has no baud "
          "rate; scripted controller answering at once)", flush=True)
    done: list = []

    def progress(r) -> None:
        done.append(r)
        if len(done) == 1:
            print(f"  28 ms for {args.duration:g} s: {r.on_time}/{r.cycles} cycles on time", flush=True)
        else:
            print(f"  {r.period_ms:g} ms for {args.search_seconds:g} s: {r.on_time}/{r.cycles} on time", flush=True)

    rows = measure_alter(args.duration, periods, args.search_seconds, mode, progress=progress)
    print("")
    cells = []
    for r in rows:
        lat50 = f"{r.pct(50, r.latency_ms):.2f} ms" if r.latency_ms else "-"
        lat99 = f"{r.pct(99, r.latency_ms):.2f} ms" if r.latency_ms else "-"
        jit = f"{r.pct(99, r.jitter_ms):.2f} ms" if r.jitter_ms else "-"
        work = [f"{r.pct(q, r.work_us):.0f}" if r.work_us else "-" for q in (50, 99)]
        h = r.histogram
        cells.append([f"{r.period_ms:g} ms", f"{r.duration_s:g} s", r.cycles, r.on_time, r.missed, lat50, lat99,
                      *(h[f"<={e:g} ms"] for e in LATENCY_EDGES_MS), jit, *work, line_capacity(r.period_ms), r.note])
    print(tables.render(["period", "run", "cycles", "on time", "missed", "reply p50", "reply p99",
                         *(f"<={e:g} ms" for e in LATENCY_EDGES_MS), "jitter p99", "work p50 us", "work p99 us",
                         "38400 line", "note"], cells, align="r" * 17 + "l"))
    print("\nreply = STATUS received -> correction sent (the gateway's side; a pty carries it at once); "
          "missed = not answered with the controller's own command, applied in its cycle. work = the "
          "gateway's serial_rx and command steps, wall time (threads mode; - over Zenoh).")
    best = shortest_sustained(rows)
    print("")
    print(f"shortest cycle period sustained without a miss: {f'{best:g} ms' if best else 'none of those tried'}"
          f" ({args.search_seconds:g} s runs)")
    return 0


def link_cycles(verb: str, text: str, allowed, what: str, length_flag: str, length_s: float) -> list[float] | None:
    """A link bench's ``--cycles`` (comma-separated ms, each one of ``allowed``) and its run
    length: the cycle times, or None after a one-line error on stderr."""
    try:
        cycle_times = [float(c) for c in text.split(",") if c.strip()]
    except ValueError:
        print(f"humanpt bench {verb}: --cycles must be numbers ({', '.join(f'{c:g}' for c in allowed)}), "
              f"got {text!r}", file=sys.stderr)
        return None
    if not cycle_times or any(c not in allowed for c in cycle_times) or not length_s > 0:
        print(f"humanpt bench {verb}: --cycles takes {what}, {length_flag} > 0; got {text!r}, {length_s:g}",
              file=sys.stderr)
        return None
    return cycle_times


def bench_rsi(args) -> int:
    """The gateway <-> the simulated RSI controller over UDP (see ``humanpt.bench.rsi``)."""
    from humanpt.bench.rsi import run_rsi

    cycle_times = link_cycles("rsi", args.cycles, (4.0, 12.0), "4 and/or 12 (RSI's cycle times)",
                              "--duration", args.duration)
    if cycle_times is None:
        return 2
    where = "a thread of this process" if args.same_process else "a process of its own"
    print(f"humanpt bench rsi (gateway <-> simulated RSI controller ({where}) over UDP on loopback; scripted "
          "command-ahead controller; no Zenoh)", flush=True)
    runs = []
    for c in cycle_times:
        n = max(1, round(args.duration * 1000.0 / c))
        r = run_rsi(c, n, robot_process=not args.same_process)
        print(f"  {c:g} ms: {r.on_time}/{r.cycles} cycles on time", flush=True)
        runs.append(r)
    print("")
    print(link_table(runs))
    print("\nlatency = robot sends <Rob> -> a valid <Sen> arrives (p50/p99 of the answers in time); late = none "
          "before the next cycle boundary. work = the gateway's udp_rx step (decode, safety rules, encode) and the "
          "command step, wall time. robot overruns = robot cycles started > 1 ms after their deadline (the simulator "
          "itself late).")
    return 0


def link_table(runs) -> str:
    """The table of a link bench's runs (``bench rsi``, ``bench ur``: :class:`humanpt.bench.rsi.RsiRun`)."""
    from humanpt.sim_robot.rsi import LATENCY_EDGES_MS

    def ms(v: float) -> str:
        return "-" if v != v else f"{v:.2f}"  # (nan: no answer)

    rows = []
    for r in runs:
        h = r.histogram
        rows.append([f"{r.cycle_ms:g} ms", r.cycles, r.on_time, f"{r.on_time_pct:.2f} %", r.late,
                     ms(r.latency_pct(50)), ms(r.latency_pct(99)), *(h[f"<={e:g} ms"] for e in LATENCY_EDGES_MS),
                     f"{r.work_pct(50):.0f}", f"{r.work_pct(99):.0f}", r.overruns, r.stopped or ""])
    return tables.render(["cycle", "cycles", "on time", "%", "late", "latency p50 ms", "latency p99 ms",
                          *(f"<={e:g} ms" for e in LATENCY_EDGES_MS), "work p50 us", "work p99 us",
                          "robot overruns", "stopped"], rows, align="r" * 16 + "l")


def bench_ur(args) -> int:
    """The gateway <-> the simulated UR controller over RTDE (see ``humanpt.bench.ur``)."""
    from humanpt.bench.ur import CYCLES_MS, run_ur

    cycle_times = link_cycles("ur", args.cycles, CYCLES_MS, "8 (CB3, 125 Hz) and/or 2 (e-Series, 500 Hz)",
                              "--seconds", args.seconds)
    if cycle_times is None:
        return 2
    where = "a thread of this process" if args.same_process else "a process of its own"
    print(f"humanpt bench ur (gateway <-> simulated UR5e controller ({where}) over RTDE, TCP on loopback; scripted "
          f"command-ahead controller; no Zenoh; {args.seconds:g} s per cycle time)", flush=True)
    runs = []
    for c in cycle_times:
        r = run_ur(c, args.seconds, robot_process=not args.same_process)
        print(f"  {c:g} ms: {r.on_time}/{r.cycles} cycles answered in time", flush=True)
        runs.append(r)
    print("")
    print(link_table(runs))
    print("\nlatency = the robot sends a cycle's data package -> the gateway's answer (the next sequence and "
          "target) is read by the robot (p50/p99 of the cycles answered); on time = read before the robot's next data "
          "package (the program's next cycle reads the registers); late = not. work = the gateway's serial_rx step "
          "(decode, safety rules, encode) and the command step, wall time. robot overruns = robot cycles started "
          "> 1 ms after their deadline (the simulator itself late). stopped: the program's watchdog (no new "
          "sequence for watchdog_cycles) stopping the arm.")
    return 0


def bench_all(args) -> int:
    """One table of the figures that matter (:func:`humanpt.bench.summary.measure_all`)."""
    from humanpt.bench.summary import measure_all

    print("humanpt bench: measuring (a shared 2-core machine is noisy: compare ratios, not digits)",
          file=sys.stderr, flush=True)
    figures, wall, failure = measure_all(
        args.live_seconds, args.lockstep_seconds, args.scenario,
        on_figure=lambda f: print(f"  {f.name}: {f.value} {f.note}", file=sys.stderr, flush=True))
    if failure:
        print(failure, file=sys.stderr)
    print(f"\nhumanpt bench (live run {args.live_seconds:g} s of {args.scenario}, {wall:.0f} s wall)\n")
    print(tables.render(["figure", "value", "note"], [[f.name, f.value, f.note] for f in figures], align="lrl"))
    return 0


def bench_bridge(args) -> int:
    """What the Foxglove bridge costs the live loop: :func:`humanpt.bench.summary.bridge_cost`."""
    from humanpt.bench.summary import bridge_cost

    if not args.seconds > 0 or args.rounds < 1:
        raise ValueError(f"--seconds must be > 0 and --rounds >= 1, got {args.seconds} and {args.rounds}")
    cost = bridge_cost(args.seconds, args.rounds, args.scenario,
                       say=lambda t: print(f"  {t}", file=sys.stderr, flush=True))
    print(f"\nhumanpt bench bridge: image-to-command latency of the live {args.scenario}, {args.rounds} x "
          f"{args.seconds:g} s each way, alternated (no browser connected)\n")
    print(tables.render(["run", "images", "p50 ms", "p50 / without", "p99 ms", "p99 / without"], cost.rows(),
                        align="lrrrrr"))
    return 0


def bench_faults(args) -> int:
    """The attacks of issues 14 and 29 against a live twin (:func:`humanpt.bench.faults.run_faults`);
    exit status 1 if one's verdict failed (not answered as it should, or the robot not held),
    2 if the twin failed (it did not start, its router never took the bench's session, a
    process died). Whether the loop stayed up is reported beside each verdict, not judged."""
    from humanpt.bench.faults import QUICK, QUICK_SECURE, format_table, run_faults

    secure = getattr(args, "secure", False)
    link = getattr(args, "link", "alter") or "alter"
    only = tuple(a.strip() for a in args.only.split(",") if a.strip()) if args.only else (
        QUICK + (QUICK_SECURE if secure else ()) if args.quick else None)
    print(f"humanpt bench faults: attacks on a live twin over {link.upper()} (router + 7 processes; reaction = "
          "injection to the first event or reply; held = largest flange step per cycle / the gateway's limit; "
          "verdict = answered as it should and held; recovered and 'loop:' = liveness, reported, not judged)"
          + ("; under mTLS, a throwaway PKI: issue 14's injections come from the key's own publisher's "
             "certificate (an insider), the bench's session is an operator's" if secure else ""),
          file=sys.stderr, flush=True)

    def on_row(r) -> None:
        state = "skipped" if r.skipped else "ok" if r.ok else "FAILED"
        print(f"  {r.key}: {state} {r.skipped or r.note}" + (f" | loop: {r.liveness}" if r.liveness else ""),
              file=sys.stderr, flush=True)

    try:
        rows, failure = run_faults(only, args.faults_scenario, args.run_dir, on_row=on_row,
                                   say=lambda t: print(f"  {t}", file=sys.stderr, flush=True), secure=secure,
                                   link=link)
    except ValueError as e:  # an unknown attack or link: the user's words
        print(f"humanpt bench faults: {e}", file=sys.stderr)
        return 2
    if rows:
        print("")
        print(format_table(rows))
    if failure:
        print(f"humanpt bench faults: {failure}", file=sys.stderr)
        return 2
    return 0 if all(r.ok for r in rows) else 1
