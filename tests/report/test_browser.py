"""Each example report in headless Chromium at 1400 and 390 px: no console error or uncaught
exception, no horizontal overflow of the page, every section present. Skipped only when no
Chromium binary is installed (MPGSPEC_CHROMIUM names one explicitly)."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from cdp_browser import Browser, find_chromium
from mpgspec import api
from mpgspec.report.files import write_project_reports
from mpgspec.report.html import render_html
from mpgspec.report.read import report_status

ROOT = Path(__file__).resolve().parents[2]
SPECS = ROOT / "specs"
EXAMPLES = ("pendulum", "cart", "a1")
WIDTHS = (1400, 390)
SECTIONS = ("summary", "graph", "assertions", "assumptions", "primitives", "edges", "grids", "switches", "failures",
            "plans", "evidence", "timing")
PROBE = """(() => {
  const d = document.documentElement;
  const wide = [...document.querySelectorAll('body *')].filter(e => {
    const r = e.getBoundingClientRect(); return r.right > innerWidth + 1 && !e.closest('.scroll, .graph, pre');
  }).slice(0, 5).map(e => e.tagName + (e.id ? '#' + e.id : '') + (e.className ? '.' + e.className : ''));
  return {width: innerWidth, scroll_width: d.scrollWidth, wide,
          ids: [...document.querySelectorAll('section[id]')].map(s => s.id),
          svgs: document.querySelectorAll('svg').length, nav_sticky: getComputedStyle(document.querySelector('nav')).position,
          details_open: document.querySelectorAll('#grids details[open], #switches details[open]').length};
})()"""


@pytest.fixture(scope="module")
def chromium() -> str:
    exe = find_chromium()
    if exe is None:
        pytest.skip("no Chromium binary (install Debian's chromium, or set MPGSPEC_CHROMIUM)")
    return exe


A1_ROBUST = """uncertainty:
  nodes: [Lie, Stand, Walk(fast)]
  parameters:
    mass_scale: {nominal: 1, range: [0.9, 1.1]}
    friction: {nominal: 0.6, range: [0.4, 0.8]}
    torque_scale: {nominal: 1, range: [0.9, 1.1]}
  disturbance: {force: {frame: trunk, bound: [7.5, 7.5, 0], duration: 0.2}, segments: 4}
  samples: 0
  search: 0
  runs: 0
  assertions:
    - edge: {from: Stand, to: Lie, class: 1}
    - edge: {from: Lie, to: Stand}
    - no_edge: {from: Stand, to: Walk(fast)}
"""


def _a1_light(root: Path) -> Path:
    """specs/a1 with its robust stage on Lie, Stand and Walk(fast) only (the graph run's first walk, whose
    edge from Stand is nominal only) and no cross-check variants: the page has every section, built in
    minutes instead of the full robust stage's compile of every primitive."""
    dst = root / "a1"
    shutil.copytree(SPECS / "a1", dst)
    text = (dst / "project.yaml").read_text()
    text = text[: text.index("\nuncertainty:")] + "\n" + A1_ROBUST
    # nor the cross-check's variants (tests/execute/test_crosscheck_variants.py shows their table)
    head, _, rest = text.partition("  variants:\n")
    (dst / "project.yaml").write_text(head + rest[rest.index("\nassertions:") + 1:] if rest else text)
    return dst


@pytest.fixture(scope="module")
def pages(tmp_path_factory, example):
    """name -> (report.html, report, errors) of an example, rendered on first use: from
    reports/<name>/report.json when `mpgspec verify` left one that matches the specs, else written
    as `mpgspec verify` writes it from the verify of specs/<name> the other modules of this test
    process read (the A1 with a light robust stage: its own verify)."""
    out = tmp_path_factory.mktemp("reports")
    cache: dict[str, tuple[Path | None, dict | None, list]] = {}

    def page(name: str):
        if name not in cache:
            report, _ = report_status(ROOT / "reports" / name / "report.json", SPECS / name / "project.yaml")
            if report is not None:
                html = out / name / "report.html"
                html.parent.mkdir(parents=True)
                html.write_text(render_html(report), encoding="utf-8")
                cache[name] = (html, report, [])
            elif name != "a1":
                p = example(name).projects[0]
                files = write_project_reports(p.report, out) if p.report is not None else {}
                cache[name] = (Path(files["html"]) if "html" in files else None, p.report, p.errors)
            else:
                p = api.verify(_a1_light(out / "specs"), out_dir=out).projects[0]
                cache[name] = (Path(p.files["html"]) if "html" in p.files else None, p.report, p.errors)
        return cache[name]

    return page


@pytest.fixture(scope="module")
def browser(chromium):
    with Browser(chromium) as b:
        yield b


@pytest.mark.slow
@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("name", EXAMPLES)
def test_report_in_chromium(pages, browser, name, width):
    html, report, errors = pages(name)
    assert html is not None, f"{name} wrote no report: {[e.get('message') for e in errors]}"
    r = browser.open(html.resolve().as_uri(), width, script=PROBE)
    assert r["errors"] == [], f"console errors in {name} at {width} px: {r['errors']}"
    v = r["value"]
    # a mobile viewport widens itself to fit content that overflows: both widths must stay at `width`
    over = max(v["scroll_width"], v["width"]) - width
    assert over <= 0, f"{name} overflows {width} px by {over} px: {v['wide']}"
    want = set(SECTIONS) | ({"sequence"} if report.get("sequence") else set())
    assert want <= set(v["ids"]), f"{name}: missing sections {sorted(want - set(v['ids']))}"
    assert v["svgs"] >= 1 + len(report["transitions"]) and v["nav_sticky"] == "sticky" and v["details_open"] == 0


@pytest.mark.slow
def test_a_run_the_cross_check_disputes_is_not_shown_as_safe(pages):
    """The A1's sequence runs: a run whose replay in MuJoCo disagrees carries a 'disputed' badge and
    the replay's first violation next to its own verdict; a run that agrees carries its verdict."""
    html, report, errors = pages("a1")
    assert html is not None, errors
    text = html.read_text(encoding="utf-8")
    runs = report["crosscheck"]["runs"]
    assert runs and set(runs) <= {"naive", "graph"}
    for mode, q in runs.items():
        start = text.index(f'<div id="run-{mode}">')
        head = text[start:text.index("</h3>", start)]
        own = "safe" if report["sequence"]["runs"][mode]["safe"] else "unsafe"
        assert (f">disputed: {own}<" in head) == (not q["agree"]) and own in head, head
        if not q["agree"] and q["mujoco"]["first_violation"]:
            assert q["mujoco"]["first_violation"]["h"] in text[start:start + 2000]


PLAYBACK_PROBE = """(async () => {
  const start = window.playback.state().t, out = {};
  for (const s of [0, %(later)s]) {
    window.playback.seek(s);
    await new Promise(r => requestAnimationFrame(() => r()));
    const c = document.getElementById('scene');
    out[s] = {state: window.playback.state(), image: c.toDataURL().length + ':' + c.toDataURL().slice(-64)};
  }
  const d = document.documentElement;
  return {frames: out, width: innerWidth, scroll_width: d.scrollWidth, hash_t: start};
})()"""


@pytest.mark.slow
@pytest.mark.parametrize("width", WIDTHS)
def test_the_a1_playback_moves_the_robot(pages, browser, tmp_path_factory, width):
    """playback.html opens offline beside the A1 report: no console error, no overflow; at two times
    the drawn robot is in another primitive, somewhere else, and the picture differs; an address with
    #t= starts there."""
    html, report, errors = pages("a1")
    assert html is not None, errors
    page = html.parent / "playback.html"
    if not page.is_file():  # the report was rendered from reports/a1: verify the light A1 for its pages
        p = api.verify(_a1_light(tmp_path_factory.mktemp("specs")), out_dir=tmp_path_factory.mktemp("out")).projects[0]
        page = Path(p.files["html"]).parent / "playback.html"
        report = p.report
    assert report["sequence"]["playback"] == "playback.html"
    later = 7.0  # Table II: Walk(fast) was commanded at 3 s
    url = page.resolve().as_uri() + "#t=5.5"
    png = tmp_path_factory.mktemp("shots") / f"playback-{width}.png"
    r = browser.open(url, width, script=PLAYBACK_PROBE % {"later": later}, screenshot=png)
    assert r["errors"] == [], r["errors"]
    v = r["value"]
    assert v["hash_t"] == pytest.approx(5.5)
    assert max(v["scroll_width"], v["width"]) <= width
    a, b = v["frames"]["0"], v["frames"][str(int(later)) if str(int(later)) in v["frames"] else str(later)]
    assert a["image"] != b["image"]
    runs_a, runs_b = a["state"]["runs"], b["state"]["runs"]
    graph_a = next(x for x in runs_a if x["name"] == "graph (mpgspec)")
    graph_b = next(x for x in runs_b if x["name"] == "graph (mpgspec)")
    assert graph_a["primitive"] == "Lie" and graph_b["primitive"].startswith("Walk")
    assert abs(graph_b["trunk"][0] - graph_a["trunk"][0]) > 0.1 and graph_b["trunk"][2] > graph_a["trunk"][2] + 0.1
    if report.get("crosscheck"):  # the simulator's replays are drawn too
        assert any("MuJoCo" in x["name"] for x in runs_a)
    assert png.stat().st_size > 10_000


FIRST_SCREEN = """(() => {
  const top = e => e ? Math.round(e.getBoundingClientRect().top) : null;
  const items = [...document.querySelectorAll('#summary li')].map(li => ({text: li.textContent, top: top(li)}));
  return {height: innerHeight, verdict: top(document.querySelector('#summary b')), items,
          page: document.documentElement.scrollHeight};
})()"""


@pytest.mark.slow
def test_the_a1_first_screen_holds_the_verdict_the_dispute_and_the_nominal_only_path(pages, browser):
    """At 1400 x 900 px the A1 report's first screen shows the verdict, every cross-check
    disagreement and the edges of the graph run's path that are nominal only; with its sections
    folded the page stays under 8,000 px."""
    from mpgspec.report.findings import disagreements, nominal_only_path

    html, report, errors = pages("a1")
    assert html is not None, errors
    r = browser.open(html.resolve().as_uri(), 1400, height=900, script=FIRST_SCREEN)
    v = r["value"]
    assert r["errors"] == [] and v["verdict"] is not None and 0 <= v["verdict"] < 900
    wanted = [f"cross-check of the {d['mode']} run" for d in disagreements(report)]
    bad = nominal_only_path(report)
    assert bad is not None, "the A1's graph run goes through edges that are nominal only"
    wanted.append(f"edges the graph run takes are nominal only (not robust to the project's uncertainty): "
                  f"{', '.join(bad['nominal_only'])}")
    for w in wanted:
        item = next((i for i in v["items"] if w in i["text"]), None)
        assert item is not None, f"not in the summary: {w}"
        assert item["top"] < v["height"], f"below the first screen ({item['top']} px): {w}"
    assert v["page"] <= 8000


GRAPH_PROBE = """(() => {
  const svg = document.querySelector('.graph svg');
  const node = [...svg.querySelectorAll('[data-node], g.node')].find(g => (g.dataset.node ||
    g.querySelector('title').textContent.trim()) === 'Lie');
  node.dispatchEvent(new MouseEvent('click', {bubbles: true}));
  const edges = [...svg.querySelectorAll('path[data-from], g.edge')];
  const faded = edges.filter(e => e.style.opacity === '0.12').length;
  const before = svg.getAttribute('viewBox');
  document.querySelector('.zoombar button').click();
  return {edges: edges.length, faded, zoomed: svg.getAttribute('viewBox') !== before};
})()"""


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["graphviz", "built-in"])
def test_clicking_a_primitive_highlights_its_edges_and_the_graph_zooms(pages, browser, tmp_path, layout, monkeypatch):
    """In the A1 report's graph, a click on Lie leaves only Lie's edges opaque; + zooms; with
    Graphviz's layout and with the built-in layered one a user without Graphviz gets."""
    _, report, errors = pages("a1")
    assert report is not None, errors
    if layout == "built-in":
        monkeypatch.setenv("MPGSPEC_GRAPHVIZ", "0")
    elif shutil.which("dot") is None:
        pytest.skip("Graphviz's dot is not installed")
    page = tmp_path / "report.html"
    page.write_text(render_html(report), encoding="utf-8")
    r = browser.open(page.resolve().as_uri(), 1400, script=GRAPH_PROBE)
    assert r["errors"] == [], r["errors"]
    v = r["value"]
    touching = sum("Lie" in (e["from"], e["to"]) for e in report["edges"])
    assert v["edges"] - v["faded"] == touching and v["faded"] > 0 and v["zoomed"]


@pytest.mark.slow
@pytest.mark.parametrize("width", WIDTHS)
def test_the_index_page_reads_at_both_widths(browser, tmp_path, width):
    from mpgspec.report.index import index_html

    (tmp_path / "sample").mkdir()
    shutil.copy(Path(__file__).parent / "data" / "sample_report.json", tmp_path / "sample" / "report.json")
    (tmp_path / "index.html").write_text(index_html(tmp_path), encoding="utf-8")
    r = browser.open((tmp_path / "index.html").resolve().as_uri(), width,
                     script="({w: innerWidth, sw: document.documentElement.scrollWidth, "
                            "rows: document.querySelectorAll('tr').length})")
    assert r["errors"] == [] and r["value"]["sw"] <= width and r["value"]["rows"] >= 3


def test_the_a1_robust_stage_keeps_the_rests_and_loses_a_walk(pages):
    """The A1's robust stage (the light one of this module, or the full one of reports/a1) passes its
    assertions: Lie <-> Stand survive the box of mass, friction and torque error with the push, and Stand ->
    Walk(fast) is lost with a worst case that says where and by how much (the walks hold their height under a
    mass error alone; with the motors 10 % weak too a landing swing foot dips below the ground)."""
    _, report, _ = pages("a1")
    rob = report["robust"]
    assert rob["assertions"] and all(a["status"] == "pass" for a in rob["assertions"]), rob["assertions"]
    edges = {(e["from"], e["to"]): e for e in rob["edges"]}
    for kept in (("Lie", "Stand"), ("Stand", "Lie")):
        assert edges[kept]["survives"] and edges[kept]["worst_margin"] > 0, edges[kept]
    lost = edges[("Stand", "Walk(fast)")]
    assert not lost["survives"] and lost["worst_margin"] < 0 and lost["cells_robust"] == 0
    bind = lost["worst_case"]["binding"]  # settled outside E_B, or a safety function left C
    assert (bind["h"] is None and bind["roa_margin"] < 0) or (bind["h"] and bind["value"] < 0), bind


def _claim(pattern: str, readme: str) -> tuple:
    """The groups of the one match of `pattern` in the README's text (whitespace-normalised); a claim
    that moved or was reworded fails here, so that its number is checked again rather than silently dropped."""
    found = re.findall(pattern, readme)
    assert len(found) == 1, f"the README should state this once: {pattern!r} (found {len(found)})"
    return found[0] if isinstance(found[0], tuple) else (found[0],)


def _as_written(value: float, text: str) -> bool:
    """Whether `value` reads as `text` to the digits written (within half a unit of the last one)."""
    digits = len(text.split(".")[1]) if "." in text else 0
    return abs(value - float(text)) <= 0.5 * 10.0 ** -digits + 1e-9


def _uncertain_runs_as_written(report: dict, readme: str) -> None:
    """The README's Table II under uncertainty is the report's, when the report ran them (the full A1 of
    reports/a1; the light A1 of this module runs none)."""
    seq = (report.get("robust") or {}).get("sequence") or {}
    if not seq.get("runs"):
        return
    n, seed = _claim(r"On the A1's Table II sequence \((\d+) runs, 22 s each, seed (\d+)\):", readme)
    assert (int(n), int(seed)) == (seq["runs"], seq["seed"])
    m = seq["modes"]
    assert int(_claim(r"naive, (\d+) of \d+ runs stay safe: trunk_clearance", readme)[0]) == m["naive"]["safe_runs"]
    for mode, words in (("graph", "nominal graph"), ("robust_graph", "robust graph")):
        safe, every, goals = _goal_claim(words, readme)
        assert (int(safe), int(every)) == (m[mode]["safe_runs"], m[mode]["reached_goal"]), mode
        assert [int(g) for g in re.findall(r"\d+", goals)] == m[mode]["goals_reached"], mode


def _goal_claim(words: str, readme: str) -> tuple:
    """(safe runs, runs in every goal, per goal) the README states for a mode through a graph."""
    return _claim(rf"- through the {words}, (\d+) of \d+ stay safe and (?:\*\*)?(\d+)[^(]*?(?:\(\d+ %\))?"
                  r"(?:\*\*)?\s*(?:are )?in every goal(?:\*\*)? \(per goal: ([\d, and]+?)(?: of \d+)?\)", readme)


def test_the_readmes_a1_graph_and_numbers_are_the_reports(pages):
    """The README's A1 numbers are the report's: the edge table (every edge and class), the oracle
    calls and edges, the radii of E it quotes and the naive run's first violations."""
    _, report, _ = pages("a1")
    assert report is not None
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    readme = " ".join(text.split())  # line breaks as spaces
    head = text.index("| from \\ to | Lie | Stand |")
    lines = text[head:].split("\n\n")[0].splitlines()
    cols = [c.strip() for c in lines[0].strip("|").split("|")][1:]
    name = {c: (f"Walk({c})" if c in ("in_place", "slow", "medium", "fast") else c) for c in cols}
    table = {}
    for row in lines[2:]:
        cells = [c.strip() for c in row.strip("|").split("|")]
        table.update({(cells[0], name[c]): int(v) for c, v in zip(cols, cells[1:]) if v})
    assert table == {(e["from"], e["to"]): int(e["class"]) for e in report["edges"]}

    calls, edges = _claim(r"builds the graph of the eight primitives \(([\d,]+) oracle calls, (\d+) edges", readme)
    assert int(calls.replace(",", "")) == report["timing"]["oracle_calls"]
    assert int(edges) == len(report["edges"])
    radius = {p["name"]: p["roa_radius"] for p in report["primitives"]}
    walk_r, fast_r, in_place_r = _claim(r"\(empirical: r = ([\d.]+) at slow and medium speed, ([\d.]+) at fast and "
                                        r"([\d.]+) in place;", readme)
    assert _as_written(radius["Walk(slow)"], walk_r) and _as_written(radius["Walk(medium)"], walk_r)
    assert _as_written(radius["Walk(fast)"], fast_r) and _as_written(radius["Walk(in_place)"], in_place_r)
    assert _as_written(radius["Lie"], _claim(r"ends inside E_Lie \(r = ([\d.]+)\)", readme)[0])
    assert _as_written(radius["Stand"], _claim(r"settles [\d.]+ \(in E's norm\) from its setpoint, outside E \(r = ([\d.]+)\)", readme)[0])

    firsts = {}
    for v in report["sequence"]["runs"]["naive"]["violations"]:
        firsts.setdefault(v["h"].split("[")[0], v)
    t_tc, t_q, t_gap, up = _claim(r"Walk\(fast\) hits `trunk_clearance` at ([\d.]+) s, then `q_min` of a calf at "
                                  r"([\d.]+) s and `touchdown_gap` at ([\d.]+) s \(a landing foot ([\d.]+) mm up at its "
                                  r"scheduled touchdown; its stance feet stay inside the friction cone", readme)
    assert _as_written(firsts["trunk_clearance"]["t"], t_tc) and _as_written(firsts["q_min"]["t"], t_q)
    gap = firsts["touchdown_gap"]  # h = 0.003 - foot_z
    assert gap["primitive"] == "Walk(fast)" and _as_written(gap["t"], t_gap)
    assert _as_written(1000 * (0.003 - gap["value"]), up)
    assert not [v for v in report["sequence"]["runs"]["naive"]["violations"]
                if v["primitive"] == "Walk(fast)" and v["h"].startswith("friction_cone")]
    t_j, f_j = _claim(r"Walk\(fast\) -> Jump leaves the friction cone at ([\d.]+) s \((-[\d.]+) N\)", readme)
    jump = [v for v in report["sequence"]["runs"]["naive"]["violations"]
            if v["primitive"] == "Jump" and v["h"].startswith("friction_cone")][0]
    assert _as_written(jump["t"], t_j) and _as_written(jump["value"], f_j)

    cc = report["crosscheck"]["runs"]
    t_both, = _claim(r"The naive run agrees: unsafe in both at ([\d.]+) s on `trunk_clearance`", readme)
    first = cc["naive"]["mujoco"]["first_violation"]
    assert cc["naive"]["agree"] and first["h"] == "trunk_clearance" and _as_written(first["t"], t_both)
    ex = cc["graph"]["executor"]
    lag, t_mj, t_mpg, t_leave, m_leave, t_jump, t_jump_mpg, t_up, t_up_mpg, t_lie, t_lie_mpg = _claim(
        r"It is safe and reaches every goal of Table II, at most ([\d.]+) s from mpgspec's run: Walk\(fast\) at "
        r"([\d.]+) s \(mpgspec ([\d.]+) s\), down through Walk\(in_place\) \(leaving Walk\(fast\) at ([\d.]+) s with "
        r"an E margin of ([\d.]+) at t_A = 0.01 s\) and Stand to Jump at ([\d.]+) s \(mpgspec ([\d.]+) s\), back up "
        r"to Walk\(fast\) at ([\d.]+) s \(mpgspec ([\d.]+) s\) and down to Lie at ([\d.]+) s \(mpgspec ([\d.]+) s\)",
        readme)
    assert ex["safe"] and ex["reached_every_goal"] and _as_written(ex["largest_lag_s"], lag)
    leave = next(s for s in ex["switches"] if (s["from"], s["to"]) == ("Walk(fast)", "Walk(in_place)"))
    assert _as_written(leave["t"], t_leave) and _as_written(leave["roa_margin"], m_leave)
    got = [(g["goal"], g["arrived"], g["arrived_mpgspec"]) for g in ex["goals"] if g["t"] > 0]
    assert [g[0] for g in got] == ["Walk(fast)", "Jump", "Walk(fast)", "Lie"]
    for (_g, mj, mpg), (w_mj, w_mpg) in zip(got, [(t_mj, t_mpg), (t_jump, t_jump_mpg), (t_up, t_up_mpg),
                                               (t_lie, t_lie_mpg)]):
        assert _as_written(mj, w_mj) and _as_written(mpg, w_mpg), (mj, w_mj, mpg, w_mpg)

    _uncertain_runs_as_written(report, readme)

    run = report["sequence"]["runs"]["graph"]
    to_jump, last = _claim(r"and Stand to Jump \(([\d.]+) s: it waits in Stand.*?down through Walk\(in_place\) to "
                           r"Lie \(([\d.]+) s\), the last goal", readme)
    switches = [(s["t"], s["to"]) for s in run["switches"]]
    assert _as_written(next(t for t, n in switches if n == "Jump"), to_jump)
    assert switches[-1][1] == "Lie" and _as_written(switches[-1][0], last) and run["safe"]
