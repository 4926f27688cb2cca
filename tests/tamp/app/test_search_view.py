"""The search view (`tamp view --search`): the page written from a record, and what a reader sees and does in it in
headless Chromium (Debian's; the browser tests skip without it)."""
from __future__ import annotations

import json
import re

import pytest

from tamp.app.cli import main
from tamp.app.search_view import DATA_ID, page, write_search_view
from tests.browser import CHROMIUM, Browser
from tests.tamp.app import search_records
from tests.tamp.app.search_records import search_record

needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium (Debian: apt-get install chromium)")


def embedded(html: str) -> dict:
    found = re.search(rf'<script type="application/json" id="{DATA_ID}">(.*?)</script>', html, re.S)
    assert found is not None
    return json.loads(found.group(1))


def test_the_page_embeds_the_record_and_loads_nothing_from_anywhere():
    record = search_record()
    record["problem"]["name"] = "p</script><script>alert(1)</script><!--"
    html = page(record)
    assert html.count("</script>") == 2 and "<!--" not in html  # the record cannot end its element
    assert embedded(html)["record"] == record
    assert "Content-Security-Policy" in html and "default-src 'none'" in html
    assert not re.search(r'\b(src|href)="(?!data:)', html)  # no script, style or image from elsewhere
    assert "<title>Search: p&lt;/script&gt;" in html


def test_the_replay_link_is_relative_to_the_page(tmp_path):
    (tmp_path / "runs").mkdir()
    record = search_record(replay=str(tmp_path / "runs" / "replay.html"))
    out = write_search_view(record, tmp_path / "views" / "search.html")
    assert embedded(out.read_text())["replay"] == "../runs/replay.html"
    assert embedded(page(search_record()))["replay"] is None


def test_tamp_view_writes_the_page_of_a_record(tmp_path, capsys):
    path = tmp_path / "run.search.json"
    path.write_text(json.dumps(search_record(n_nodes=30, rounds=2)))
    assert main(["view", "--search", str(path)]) == 0
    out = capsys.readouterr().out
    assert "2 round(s), 2 executed step(s); Level 1: 4 candidate plan(s); Level 2: 30 node(s)" in out
    written = tmp_path / "run.search.html"
    assert f"search view written to {written}" in out and embedded(written.read_text())["record"]["version"] == 1


RECORD = json.dumps(search_record(n_nodes=20, rounds=1))
MISSING = json.loads(RECORD)
del MISSING["rounds"][0]["level2"]["nodes"][3]["g"]


@pytest.mark.parametrize("content, said", [
    ("{not json", "not valid JSON"),
    (RECORD[:len(RECORD) // 2], "not valid JSON"),  # truncated
    ('{"format": "tamp-search-record", "version": 1, "rounds": ' + "[" * 40 + "]" * 40 + "}", "deep"),  # a bomb
    ('{"format": "tamp-steps", "version": 1}', "not a tamp search record"),
    (RECORD.replace('"version":1', '"version":7').replace('"version": 1', '"version": 7'), "version 7"),
    (json.dumps(MISSING), "rounds[0].level2.nodes[3]: missing field 'g'"),
])
def test_tamp_view_refuses_a_bad_record_in_one_line(tmp_path, capsys, content, said):
    path, out = tmp_path / "bad.json", tmp_path / "bad.html"
    path.write_text(content)
    assert main(["view", "--search", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"tamp view: error: {path}") and said in err
    assert not out.exists()
    assert main(["view", "--search", str(tmp_path / "absent.json")]) == 2


# ---------- in a browser ----------

@pytest.fixture(scope="module")
def browser():
    if CHROMIUM is None:
        pytest.skip("needs Chromium (Debian: apt-get install chromium)")
    with Browser() as b:
        yield b


@pytest.fixture(scope="module")
def view(tmp_path_factory):
    """A page of two rounds: round 0's Level 2 tree of 60 nodes, round 1 kept on course; a replay beside it."""
    folder = tmp_path_factory.mktemp("view")
    (folder / "replay.html").write_text("<!DOCTYPE html><title>replay</title>")
    record = search_record(n_nodes=60, rounds=2, replay=str(folder / "replay.html"))
    return write_search_view(record, folder / "search.html"), record


def rows(browser) -> list[dict]:
    return browser.eval("Array.from(document.querySelectorAll('#tree .row')).map(r => ({id: JSON.parse("
                        "r.dataset.id), cls: r.className}))")


def caption(browser) -> str:
    """What the scene panel says it draws."""
    return browser.eval("document.getElementById('scene-caption').textContent")


def choose(browser, selector: str, value: str, event: str) -> None:
    """Set a form control as a reader would, and fire the event the page listens to."""
    browser.eval(f"(() => {{ const e = document.querySelector({json.dumps(selector)}); e.value = {json.dumps(value)};"
                 f" e.dispatchEvent(new Event({json.dumps(event)}, {{bubbles: true}})); }})()")


@pytest.mark.slow
@needs_chromium
def test_the_page_loads_without_an_error_and_shows_each_round(browser, view):
    path, record = view
    browser.open(path)
    assert browser.errors() == []
    tabs = browser.eval("Array.from(document.querySelectorAll('nav.tabs button')).map(b => b.textContent)")
    assert tabs == ["Round 0planned; missed by 1.0 cm", "Round 1kept on course; missed by 2.0 cm"]
    assert "landed 1.0 cm from the prediction" in browser.eval("document.querySelector('.round-summary').textContent")
    browser.click('nav.tabs button[data-round="1"]')
    assert browser.eval("location.hash").startswith("#round=1")
    assert "Level 2 did not run" in browser.eval("document.getElementById('level2').textContent")
    # the chosen plan's refinement, each executed action linked to the replay at its step
    assert browser.eval("document.querySelector('#refinement a').getAttribute('href')") == "replay.html#step=2"
    browser.click("#show-executed")
    assert caption(browser) == ("executed pick 0 at centre \u2192 place on 1 at +7.5 cm; landed 2.0 cm from the "
                                "prediction")
    assert browser.errors() == []
    # an address that names nothing of the record opens the page as it opens without one
    browser.open(path, "round=9&select=nabc&t=zz&filter=reason:nothing&state=-1")
    assert browser.errors() == [] and browser.eval("location.hash") == "#round=0&select=nabc"
    assert rows(browser) and browser.eval("document.getElementById('filter').value") == "all"


@pytest.mark.slow
@needs_chromium
def test_expanding_the_tree_and_clicking_a_node_draws_its_scene(browser, view):
    path, record = view
    nodes = {n["id"]: n for n in record["rounds"][0]["level2"]["nodes"]}
    browser.open(path, "round=0")
    before = rows(browser)
    closed = next(r["id"] for r in before if browser.eval(
        f"document.querySelector('#tree .row[data-id=\"{r['id']}\"] [aria-expanded=false]') !== null"))
    browser.click(f'#tree .row[data-id="{closed}"] [data-toggle]')
    after = rows(browser)
    children = [n for n in nodes.values() if n["parent"] == closed]
    assert len(after) == len(before) + len(children)
    child = children[-1]
    browser.click(f'#tree .row[data-id="{child["id"]}"] .act')
    assert caption(browser).startswith(f"Level 2 node #{child['id']}")
    # its predicted scene: each of the 3 blocks in the top and side views, with the goal's outlines
    blocks = browser.eval("document.querySelectorAll('.scene.predicted svg rect[fill-opacity]').length")
    goals = browser.eval("document.querySelectorAll('.scene.predicted svg rect[stroke-dasharray]').length")
    assert blocks == 6 and goals == 6
    xs = browser.eval("Array.from(document.querySelectorAll('.scene.predicted svg.top rect[fill-opacity]'))"
                      ".map(r => +r.getAttribute('x'))")
    assert len(set(xs)) > 1
    # a Level 1 candidate draws its states, one at a time
    browser.click('.cand[data-index="1"] ol')
    assert caption(browser).startswith("Level 1 candidate, state after")
    assert browser.eval("document.querySelectorAll('.stepper button').length") == 2
    assert browser.errors() == []


@pytest.mark.slow
@needs_chromium
def test_the_filters_and_the_timeline_change_what_the_tree_shows(browser, view):
    path, record = view
    level2 = record["rounds"][0]["level2"]
    browser.open(path, "round=0")
    choose(browser, "#filter", "path", "change")
    assert [r["id"] for r in rows(browser)] == level2["path"]
    assert all("path" in r["cls"] for r in rows(browser))
    choose(browser, "#filter", "rejected", "change")
    shown = rows(browser)
    rejected = {n["id"] for n in level2["nodes"] if n["verdict"] != "ok"}
    assert rejected and {r["id"] for r in shown if "rejected" in r["cls"]} == rejected
    assert all(r["id"] in rejected or "rejected" not in r["cls"] for r in shown)  # the rest are their ancestors
    choose(browser, "#filter", "reason:IK", "change")
    ik = {r["id"] for r in rows(browser) if "rejected" in r["cls"]}
    assert ik == {n["id"] for n in level2["nodes"] if n["verdict"] == "IK"}
    assert browser.eval("location.hash") == "#round=0&select=n%s&filter=reason%%3AIK" % level2["path"][-1]
    choose(browser, "#filter", "reason:" + search_records.REASONS[-1], "change")  # a reason that looks like HTML
    chips = browser.eval("Array.from(document.querySelectorAll('#tree .chip.bad')).map(c => c.textContent)")
    assert chips and set(chips) == {search_records.REASONS[-1]}
    assert browser.eval("document.querySelectorAll('#tree i').length") == 0
    # the timeline: after 2 expansions only the root's and the 2nd expanded node's successors exist
    choose(browser, "#filter", "all", "change")
    choose(browser, "#timeline", "2", "input")
    second = next(n for n in level2["nodes"] if n["order"] == 1)
    seen = {r["id"] for r in rows(browser)}
    assert seen <= {0} | {n["id"] for n in level2["nodes"] if n["parent"] in (0, second["id"])}
    assert [r["id"] for r in rows(browser) if "current" in r["cls"]] == [second["id"]]
    orders = browser.eval("Array.from(document.querySelectorAll('#tree .row .ord')).map(o => o.textContent)")
    assert set(orders) <= {"exp 1", "exp 2", "--"} and "exp 2" in orders
    assert browser.eval("document.getElementById('timeline-label').textContent") == \
        f"after expansion 2 of {level2['expanded']}"
    browser.click("#play")  # the replay runs the timeline on from the start to the end
    browser.eval("new Promise(r => setTimeout(r, 120))")
    assert browser.eval("document.getElementById('timeline-label').textContent").startswith("after expansion ")
    browser.eval("new Promise(r => { const w = () => document.getElementById('timeline-label').textContent"
                 ".startsWith('all') ? r() : setTimeout(w, 50); w(); })")
    assert browser.eval("+document.getElementById('timeline').value") == level2["expanded"]
    assert browser.errors() == []


@pytest.mark.slow
@needs_chromium
def test_a_1500_node_tree_opens_lazily(browser, tmp_path):
    """Collapsed successors are not in the page until expanded: 1,500 nodes open with a few rows in the DOM (the
    render time is measured by bench/search_view.py)."""
    path = write_search_view(search_record(n_nodes=1500, rounds=1), tmp_path / "big.html")
    browser.open(path)
    assert browser.errors() == []
    assert browser.eval("document.querySelectorAll('#tree .row').length") < 100
    browser.click("#expand-all")
    assert browser.eval("document.querySelectorAll('#tree .row').length") == 1500
    assert browser.eval("document.getElementById('tree-count').textContent") == "1500 of 1500 nodes in view"
