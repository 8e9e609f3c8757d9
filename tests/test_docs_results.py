"""The README's numbers come from the result records, and the docs keep history out of reference pages.

- The README's rendered blocks equal what ``tools/results.py render`` makes from ``docs/results/data/*.json``.
- Outside those blocks (and outside code) the README holds no number but a short list of names (Python 3.11,
  Table 6, 6-DoF, the notebook numbers, the thesis's year and report number).
- Every record names its command, data, commit, date and a docs page that exists.
- No docs page outside CHANGELOG.md and docs/archive.md holds a date or a tracker reference ("issue 23"); a results
  page names the commits its numbers were measured at, and the records under docs/results/data/ hold the dates.
- Every relative link in README.md and docs/ points at a file that exists, and at a heading that exists.
"""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("evio_tools_results", ROOT / "tools" / "results.py")
results = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(results)

HISTORY_PAGES = {ROOT / "CHANGELOG.md", ROOT / "docs" / "archive.md"}


def _docs_pages() -> list[Path]:
    return sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])


def test_readme_blocks_are_rendered_from_the_records():
    assert results.check_readme() == [], "run `python tools/results.py render`"


def _prose(text: str) -> str:
    """Return ``text`` without the rendered blocks, fenced code, inline code, link targets and HTML comments."""
    text = re.sub(r"<!-- rendered by tools/results\.py.*?<!-- end of [a-z]+ -->", "", text, flags=re.S)
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = re.sub(r"`[^`]*`", "", text)
    text = re.sub(r"\]\([^)]*\)", "]", text)
    return re.sub(r"<!--.*?-->", "", text, flags=re.S)


#: the numbers the README may hold outside its rendered blocks: names, not measurements.
ALLOWED_NUMBERS = {"3.11", "6", "2020", "20", "021"}


def test_readme_holds_no_number_outside_the_rendered_blocks():
    prose = _prose((ROOT / "README.md").read_text(encoding="utf-8"))
    numbers = re.findall(r"(?<![\w.])\d+(?:\.\d+)?", prose)
    stray = sorted(set(numbers) - ALLOWED_NUMBERS)
    assert not stray, f"README.md numbers outside the rendered blocks: {stray} (render them from a record)"


def test_readme_is_a_front_page():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 120, f"README.md has {len(lines)} lines (a front page: at most 120)"


def test_prose_check_finds_a_stray_number():
    assert re.findall(r"(?<![\w.])\d+(?:\.\d+)?", _prose("SIFT reaches 0.39 % `run 5` [a](b1.md)")) == ["0.39"]


@pytest.mark.parametrize("path", sorted(results.DATA_DIR.glob("*.json")), ids=lambda p: p.stem)
def test_every_record_is_complete(path):
    record = json.loads(path.read_text(encoding="utf-8"))
    assert record["name"] == path.stem
    for key in ("command", "data", "commit", "date", "machine", "page", "values"):
        assert record.get(key), f"{path.name}: {key!r} is missing or empty"
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", record["date"])
    page = ROOT / record["page"].split("#")[0]
    assert page.is_file(), f"{path.name}: page {record['page']} does not exist"


def test_every_record_is_used_by_the_readme():
    values = results.Values()
    results.render_blocks()
    for _, template, name in results.HEADLINE:
        results.fill(template, values)
    results.fill(results.TIMES_TEMPLATE, values)
    unused = {p.stem for p in results.DATA_DIR.glob("*.json")} - values.used
    assert not unused, f"records no README row renders: {sorted(unused)}"


def test_a_missing_marker_is_refused():
    with pytest.raises(ValueError, match="lacks the markers"):
        results.apply_blocks("no markers here", {"headline": "x"})


_DATE = re.compile(r"\b20\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b")
_TRACKER = re.compile(r"\b[Ii]ssues? \d+\b")


@pytest.mark.parametrize("path", [p for p in _docs_pages() if p not in HISTORY_PAGES],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_no_dates_or_tracker_words_outside_the_history_pages(path):
    lines = path.read_text(encoding="utf-8").splitlines()
    dated = [line.strip()[:100] for line in lines if _DATE.search(line) or _TRACKER.search(line)]
    assert not dated, f"{path.relative_to(ROOT)}: dated or tracker lines (history goes to CHANGELOG.md): {dated[:5]}"


def _slug(heading: str) -> str:
    """Return GitHub's anchor of a markdown heading."""
    text = re.sub(r"`", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    anchors, seen = set(), {}
    in_code = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code:
            continue
        m = re.match(r"#{1,6}\s+(.*)", line)
        if m:
            slug = _slug(m.group(1))
            n = seen.get(slug, 0)
            anchors.add(slug if n == 0 else f"{slug}-{n}")
            seen[slug] = n + 1
    return anchors


def test_slug_follows_github():
    assert _slug("Faster motion (`--speed`): where the events pay off") == "faster-motion---speed-where-the-events-pay-off"


@pytest.mark.parametrize("path", _docs_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        if not dest.exists():
            broken.append(target)
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(target)
    assert not broken, f"{path.relative_to(ROOT)}: broken links {broken}"
