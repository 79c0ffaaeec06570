"""The speed tables of docs/results.md: the live page's frames per second and edit-to-pixel latency
(``scripts/measure_live_fps.py``), the soak (``scripts/soak_live.py``), the pipeline's profile
(``scripts/profile_pipeline.py``) and a paired bench of two commits (``scripts/paired_bench.py``). Each takes a
:class:`lftransfer.reports.results.StoredRun`."""

from __future__ import annotations

from lftransfer.reports.results_format import fixed, median_p95, num, table

__all__ = ["live_fps_tables", "paired_tables", "profile_tables", "soak_tables"]


def _setting(d: dict) -> list[str]:
    view, lf = d.get("view") or ["?", "?"], d.get("lf_camera")
    load = (d.get("machine") or {}).get("load_average")
    return [f"View {view[0]} x {view[1]}" + (f", LF camera {lf[0]} x {lf[1]}" if d.get("lf_camera") else "")
            + f"; rig model {d.get('rig_model')}"
            + (f" ({d['calibration']})" if d.get("calibration") else "")
            + (f"; load average at the end {' / '.join(num(x, 2) for x in load)}" if load else "") + ".", ""]


def live_fps_tables(s) -> list[str]:
    loops = s.need("loops")
    out = _setting(s.data)
    names = list(loops)
    rows = [["frames per second on the page", *(num(loops[k].get("frames_per_second")) for k in names)],
            ["edit-to-pixel latency, ms: median (95 %)",
             *(median_p95(loops[k].get("edit_to_pixel_ms")) for k in names)],
            ["motion to composite, ms (the session's own clock)",
             *(median_p95((loops[k].get("latency_ms") or {}).get("view")) for k in names)],
            ["motion to its light on the real objects, ms",
             *(median_p95((loops[k].get("latency_ms") or {}).get("light")) for k in names)],
            ["captures per second", *(num(loops[k].get("capture_hz")) if loops[k].get("capture_hz") else
                                      "one per frame" for k in names)],
            ["longest gap between frames, s", *(num(loops[k].get("longest_gap_s")) for k in names)],
            ["the simulator renders in", *(f"{loops[k]['simulator']} ({_cores(loops[k].get('cores_busy'))})"
                                          if loops[k].get("simulator") else "-" for k in names)],
            ["edits sent (one every ... s)", *(f"{loops[k].get('edits_sent')} ({num(loops[k].get('edit_every_s'))})"
                                               for k in names)]]
    stages = {k: loops[k].get("last_frame_stages_ms") or {} for k in names}
    for stage in dict.fromkeys(x for k in names for x in stages[k] if x != "total"):
        rows.append([f"last frame: `{stage}`, ms", *(fixed(stages[k].get(stage), 1) for k in names)])
    captured = {k: loops[k].get("last_capture_ms") or {} for k in names}
    for stage in dict.fromkeys(x for k in names for x in captured[k]):
        rows.append([f"its capture: `{stage}`, ms", *(fixed(captured[k].get(stage), 1) for k in names)])
    return out + table(["quantity", *names], rows)


def _cores(busy: dict | None) -> str:
    """The cores each side kept busy over the page's last frames (``cores_busy`` of its frame message)."""
    if not busy:
        return "cores busy not measured"
    sim = busy.get("simulator")
    return f"cores busy of {busy.get('cores')}: the loop {num(busy.get('loop'))}" + \
        ("" if sim is None else f", the simulator {num(sim)}")


def simulator_places_tables(s, names: list[str]) -> list[str]:
    """The decoupled loop of ``lft bench --live`` with the simulator in each place (kind ``simulator_places``:
    ``data[name]``, one bench JSON each): the render rate beside it and alone, the captures' rate, the cores."""
    rows = []
    for name in names:
        dec = s.need(name, "decoupled")
        sim = dec.get("simulator") or {}
        turns = f", in turns ({fixed(100 * sim['share'], 0)} % of the time)" if sim.get("share") else ""
        where = f"own process, nice {sim.get('nice')}, {sim.get('threads')} thread(s){turns}" \
            if sim.get("where") == "process" else "the loop's process"
        light = ((dec.get("latency") or {}).get("light") or {}).get("median")
        rows.append([where, num(dec.get("render_fps")), num(dec.get("render_fps_alone")),
                     f"{fixed(100 * dec['rate_with_simulator'], 0)} %" if dec.get("rate_with_simulator") else "-",
                     num(dec.get("capture_hz")), fixed(light, 0), num(dec.get("cores_busy")),
                     num(dec.get("simulator_cores_busy")) if dec.get("simulator_cores_busy") is not None else
                     "(in the loop's)"])
    return ["Each row is one `lft bench --live` run, one after another on one machine; the rate alone is "
            "the same loop with the captures held, in the same run (target: at least 70 % kept).", ""] + \
        table(["the simulator renders in", "frames/s beside it", "frames/s alone", "kept", "captures/s",
               "motion to its light, ms (median)", "loop's cores busy", "simulator's cores busy"], rows)


def soak_tables(s) -> list[str]:
    d = s.data
    rss = s.need("rss_mb")
    out = _setting(d)
    rows = [["minutes, loop", f"{num(d.get('minutes'))}, {d.get('loop')}"],
            ["resident memory, MB: at 1 min / at the end / largest",
             " / ".join(num(x) for x in (next((mb for t, mb in rss if t >= 60), None), rss[-1][1] if rss else None,
                                         max((mb for _, mb in rss), default=None)))],
            ["growth after the first minute (limit)", f"{num(100 * d['rss_growth_after_first_minute'], 2)} % "
                                                      f"({num(100 * d.get('rss_growth_limit', 0.05), 2)} %)"
             if d.get("rss_growth_after_first_minute") is not None else "-"],
            ["memory flat", num(d.get("memory_flat"))],
            ["frames, frames per second", f"{d.get('frames')}, {num(d.get('frames_per_second'))}"],
            ["longest gap between frames, s (limit)", f"{num(d.get('longest_gap_s'))} ({num(d.get('stall_limit_s'))})"],
            ["edit-to-pixel, ms: median (95 %), largest",
             f"{median_p95(d.get('edit_to_pixel_ms'))}, {fixed(d.get('edit_to_pixel_max_ms'), 0)}"],
            ["edits sent, not seen", f"{d.get('edits_sent')}, {d.get('edits_unseen')}"],
            ["no frame stalled", num(d.get("no_stall"))]]
    return out + table(["quantity", "value"], rows)


def profile_tables(s) -> list[str]:
    d = s.data
    stages = s.need("stages_ms")
    res = d.get("resolution") or {}
    out = [f"The pipeline's stages repeated {d.get('repeats')} times on one frame's capture, without the simulator; "
           f"LF camera {res.get('lf_camera')}, projector {res.get('projector')}, view {res.get('view')}"
           + (f"; the code of commit {d['source']['commit'][:7]}" if isinstance(d.get("source"), dict) else "")
           + ".", ""]
    out += table(["stage", "ms (median)"], [[f"`{k}`", fixed(v, 1)] for k, v in stages.items()])
    spy = d.get("py_spy")
    if isinstance(spy, dict):
        out += [f"py-spy over those stages ({spy.get('samples')} samples; the script again under `py-spy record "
                "--native --format raw --rate 100`): the functions with the most samples, per cent.", ""]
        own, inclusive = spy.get("self") or [], spy.get("inclusive") or []
        n = max(len(own), len(inclusive))
        cell = lambda xs, i: f"`{xs[i][0]}` {num(xs[i][1])}" if i < len(xs) else ""   # noqa: E731
        out += table(["self", "inclusive"], [[cell(own, i), cell(inclusive, i)] for i in range(min(n, 12))])
    return out


def paired_tables(s) -> list[str]:
    d = s.data
    rows = s.need("rows")
    a, b = s.need("a"), s.need("b")
    machine = d.get("machine") or {}
    load = [machine.get("load_average_start"), machine.get("load_average_end")]
    out = [f"A = {a.get('label')}, B = {b.get('label')}: `lft bench {' '.join(d.get('bench_args') or [])}`, "
           f"{d.get('rounds')} benches each, alternated (A B, B A, ...); per figure the median over the benches of "
           "each bench's own median, the lowest and highest of those, and the ratio B / A (below 1: B is faster)"
           + (f"; load average (1, 5, 15 min) {' / '.join(fixed(x, 2) for x in load[0])} at the start, "
              f"{' / '.join(fixed(x, 2) for x in load[1])} at the end" if all(load) else "") + ".", ""]

    def cell(v, r) -> str:
        return "-" if v is None else f"{fixed(v, 1)} ({fixed(r[0], 1)} to {fixed(r[1], 1)})"

    return out + table(["figure, ms", "A", "B", "B / A"],
                       [[f"`{r['figure']}`", cell(r.get("a_ms"), r.get("a_range")),
                         cell(r.get("b_ms"), r.get("b_range")), num(r.get("ratio"))] for r in rows])
