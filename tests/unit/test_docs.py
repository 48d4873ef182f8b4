"""The documents are a reference a newcomer can follow: every link resolves, nothing points
outside the repository, no user document names a work item, and the front door and the figures'
reference stay short and wrapped (README.md at most 250 lines, docs/performance.md at most 600,
both at 100 columns outside table rows).

Each rule is a function of the repository root that lists its violations, so the tests below
also show it finding one in a small tree made for the purpose.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import isac_mission

ROOT = Path(__file__).resolve().parents[2]

LINE_LIMITS = {"README.md": 250, "docs/performance.md": 600}
"""Documents with a length budget (lines)."""
WRAPPED = ("README.md", "docs/performance.md", "docs/model.md", "CHANGELOG.md")
"""Documents wrapped at WIDTH columns (table rows exempt: a row is one line)."""
WIDTH = 100

_FENCE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s+<?(\S+?)>?(?:\s|$)", re.MULTILINE)
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$", re.MULTILINE)
_WORK_ITEM = re.compile(r"\b(?:issues?|items?)\s+#?\d+", re.IGNORECASE)
_CITATION = re.compile(
    r"(docs/[\w/.-]+\.md|README\.md|(?<![\w/.])[\w-]+\.md)[`)\]]*,?\s+"
    r"(?:\"([^\"]{3,80})\"|'([^']{3,80})'|(Tables? \d+))"
)
"""A citation of a document's section in prose or code: `docs/model.md, "Safety"` (or 'Safety'),
`model.md, "Safety"` from another doc, `docs/performance.md, Table 4`."""
_CITING = (".py", ".md", ".sh", ".yaml", ".yml", ".toml", "")
_OUTSIDE = re.compile(r"\.\./shared|/work/|PAPER-NOTES|LIBRARY-NOTES")


def documents(root: Path) -> list[Path]:
    """README.md, CHANGELOG.md and every Markdown file under docs/, sorted."""
    found = [root / name for name in ("README.md", "CHANGELOG.md") if (root / name).is_file()]
    return found + sorted((root / "docs").rglob("*.md"))


def _rel(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def _prose(text: str) -> str:
    """The text without fenced code blocks (a link in a code block is code, not a link)."""
    return _FENCE.sub("", text)


def anchors(text: str) -> set[str]:
    """The anchors GitHub gives the headings of a Markdown text: lowercase, every character
    that is not a letter, digit, space, hyphen or underscore dropped, spaces as hyphens, the
    n-th repeat of a slug suffixed -n."""
    seen: dict[str, int] = {}
    out: set[str] = set()
    for match in _HEADING.finditer(_prose(text)):
        title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", match.group(2))
        slug = re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        out.add(slug if n == 0 else f"{slug}-{n}")
        seen[slug] = n + 1
    return out


def link_targets(text: str) -> list[str]:
    """Every link target of a Markdown text outside code blocks (inline, image, reference)."""
    prose = _prose(text)
    return [m.group(1) for m in _LINK.finditer(prose)] + _REFERENCE.findall(prose)


def broken_links(root: Path) -> list[str]:
    """Relative links of the documents that do not resolve inside the repository: the file
    is missing, it lies outside root, or the #anchor names no heading of the target."""
    out: list[str] = []
    for doc in documents(root):
        for target in link_targets(doc.read_text(encoding="utf-8")):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):
                continue  # a web address or mailto: not a file of the repository
            where, _, anchor = target.partition("#")
            path = (doc.parent / where).resolve() if where else doc
            what = f"{_rel(doc, root)}: {target}"
            if not path.is_relative_to(root.resolve()):
                out.append(f"{what} points outside the repository")
            elif not path.exists():
                out.append(f"{what}: no such file")
            elif (
                anchor
                and path.suffix == ".md"
                and anchor not in anchors(path.read_text(encoding="utf-8"))
            ):
                out.append(f"{what}: no heading #{anchor} in {_rel(path, root)}")
    return out


def work_items(root: Path) -> list[str]:
    """Lines of the documents and the shipped scenarios that name a work item ("issue 13",
    "item 2")."""
    scenarios = sorted((root / "isac_mission" / "scenarios").glob("*.yaml"))
    return [
        f"{_rel(doc, root)}:{n}: {line.strip()}"
        for doc in [*documents(root), *scenarios]
        for n, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1)
        if _WORK_ITEM.search(line)
    ]


def outside_pointers(root: Path, files: list[str]) -> list[str]:
    """Lines of the given files (relative to root) that point at a path outside the
    repository (the workplace's shared folder or an absolute /work/ path)."""
    out: list[str] = []
    for rel in files:
        path = root / rel
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except (UnicodeDecodeError, FileNotFoundError):
            continue
        out += [f"{rel}:{n}" for n, line in enumerate(lines, 1) if _OUTSIDE.search(line)]
    return out


def _flat(text: str) -> str:
    """The text on one line: each line's indentation and comment mark dropped, so that a
    citation broken over two lines of a comment or docstring reads whole."""
    return " ".join(re.sub(r"^\s*(#\s?)?", "", line) for line in text.splitlines())


def _cited_file(citing: str, doc: str, root: Path) -> Path:
    """The document a citation names: a path from the root, or a bare name beside the citing
    document or under docs/."""
    if doc.startswith(("docs/", "README")):
        return root / doc
    beside = (root / citing).parent / doc
    return beside if beside.is_file() else root / "docs" / doc


def _title(text: str) -> str:
    return re.sub(r"[`*]", "", text).strip().lower()


def stale_citations(root: Path, files: list[str]) -> list[str]:
    """Citations of a document's section (see _CITATION) in the given files that name no
    heading of that document: a cited title must begin a heading or lie within one."""
    out: list[str] = []
    for rel in files:
        path = root / rel
        if path.suffix not in _CITING or not path.is_file():
            continue
        try:
            text = _flat(path.read_text(encoding="utf-8"))
        except UnicodeDecodeError:
            continue
        for match in _CITATION.finditer(text):
            cited = _cited_file(rel, match.group(1), root)
            if not cited.is_file():
                continue  # a bare name that is no document here (a link checks files)
            titles = [
                _title(h.group(2))
                for h in _HEADING.finditer(_prose(cited.read_text(encoding="utf-8")))
            ]
            want = _title(match.group(2) or match.group(3) or match.group(4))
            if not any(t.startswith(want) or want in t for t in titles):
                out.append(f"{rel}: {match.group(1)}, {want!r}: no such section")
    return out


def budget_violations(root: Path) -> list[str]:
    """Documents over their line budget, and lines wider than WIDTH in the wrapped ones
    (table rows and lines of code blocks that hold a single unbreakable word excepted)."""
    out = [
        f"{rel}: {n} lines (at most {limit})"
        for rel, limit in LINE_LIMITS.items()
        if (n := len((root / rel).read_text(encoding="utf-8").splitlines())) > limit
    ]
    for rel in WRAPPED:
        path = root / rel
        if not path.is_file():
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if len(line) > WIDTH and not line.lstrip().startswith("|") and " " in line.strip():
                out.append(f"{rel}:{n}: {len(line)} columns")
    return out


SOURCE_FOLDERS = ("isac_mission", "sim", "tests", "bench", "scripts", "docs", ".ci")
"""The folders of the project's own files (beside the files at the top); caches, virtual
environments and outputs lie elsewhere."""


def _project_files() -> list[str]:
    """The project's text files, relative to ROOT: the files at the top and those under
    SOURCE_FOLDERS, caches left out (no subprocess: the fast tier starts none)."""
    found = [p for p in ROOT.iterdir() if p.is_file()]
    for folder in SOURCE_FOLDERS:
        found += [p for p in (ROOT / folder).rglob("*") if p.is_file()]
    return sorted(
        _rel(p, ROOT)
        for p in found
        if "__pycache__" not in p.parts and p.suffix not in {".pyc", ".png", ".so", ".c"}
    )


# --------------------------------------------------------------------------------------------
# The repository keeps the rules


def test_every_link_of_the_documents_resolves() -> None:
    assert len(documents(ROOT)) >= 10
    assert broken_links(ROOT) == []


def test_no_user_document_names_a_work_item() -> None:
    assert work_items(ROOT) == []


def test_no_file_of_the_project_points_outside_the_repository() -> None:
    files = [f for f in _project_files() if f != "tests/unit/test_docs.py"]
    assert len(files) > 100
    assert outside_pointers(ROOT, files) == []


def test_every_cited_section_exists() -> None:
    files = [f for f in _project_files() if f != "tests/unit/test_docs.py"]
    assert stale_citations(ROOT, files) == []


def test_the_front_door_and_the_figures_keep_their_budget() -> None:
    assert budget_violations(ROOT) == []


def test_the_changelog_has_a_section_for_this_version() -> None:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert re.search(
        rf"^## \[{re.escape(isac_mission.__version__)}\] - \d{{4}}-\d\d-\d\d$", text, re.M
    )
    assert "## [Unreleased]" in text


# --------------------------------------------------------------------------------------------
# The rules find what they must


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return tmp_path


def test_anchors_follow_the_github_slug_rule() -> None:
    text = "# The model: eq. (8)\n## `planner.horizon.*` keys\n## Same\n## Same\n## a_b c\n"
    assert anchors(text) == {"the-model-eq-8", "plannerhorizon-keys", "same", "same-1", "a_b-c"}
    assert "planner.horizon.*" not in anchors(text)


@pytest.mark.parametrize(
    ("link", "what"),
    [
        ("[a](docs/missing.md)", "no such file"),
        ("[a](docs/b.md#nowhere)", "no heading #nowhere"),
        ("[a](../outside.md)", "points outside the repository"),
        ("![console](docs/missing.png)", "no such file"),
        ("[a][ref]\n\n[ref]: docs/gone.md", "no such file"),
    ],
)
def test_a_broken_link_is_found(tmp_path: Path, link: str, what: str) -> None:
    root = _tree(tmp_path, {"README.md": f"# Top\n{link}\n", "docs/b.md": "# B\n## Here\n"})
    found = broken_links(root)
    assert len(found) == 1 and what in found[0], found


def test_good_links_web_addresses_and_code_blocks_pass(tmp_path: Path) -> None:
    readme = (
        "# Top\n[b](docs/b.md#here) [self](#top) [web](https://example.org/x.md)\n"
        "```\n[not a link](nowhere.md)\n```\n"
    )
    root = _tree(tmp_path, {"README.md": readme, "docs/b.md": "# B\n## Here\n[up](../README.md)\n"})
    assert broken_links(root) == []


def test_a_stale_citation_is_found(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "docs/model.md": "# Model\n## Safety (`planner.safety_margin`)\n## Receding horizon\n",
            "docs/service.md": 'See model.md, "Safety" and [model](model.md), "Gone".\n',
            "pkg/a.py": (
                '"""The rule (docs/model.md,\n    "Receding horizon"); docs/model.md, Table 4."""\n'
                "# docs/model.md, 'Evasion'\n"
            ),
        },
    )
    assert stale_citations(root, ["docs/service.md", "pkg/a.py"]) == [
        "docs/service.md: model.md, 'gone': no such section",
        "pkg/a.py: docs/model.md, 'table 4': no such section",
        "pkg/a.py: docs/model.md, 'evasion': no such section",
    ]


def test_work_items_pointers_and_budgets_are_found(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "README.md": "# Top\n" + "x\n" * 250,
            "docs/performance.md": "# P\nmeasured for issue 13\n" + ("word " * 30) + "\n",
            "docs/model.md": "| " + "cell | " * 40 + "\n",
            "notes.txt": "see ../shared/paper.tex\n",
        },
    )
    assert work_items(root) == ["docs/performance.md:2: measured for issue 13"]
    assert outside_pointers(root, ["notes.txt", "README.md"]) == ["notes.txt:1"]
    assert budget_violations(root) == [
        "README.md: 251 lines (at most 250)",
        "docs/performance.md:3: 150 columns",
    ]
