"""The documentation's links and file names point at files that exist in the repository.

Checked files: README.md, datasets/README.md and every docs/**/*.md. In each, every relative Markdown link
target (``[text](path)``, ``![alt](path)``, ``[ref]: path``; http(s)://, mailto: and pure ``#anchor`` links are
skipped, ``#anchor`` suffixes stripped) must exist relative to the file that contains it, and every path-like
token naming a ``.md`` file (``docs/formats.md``, ``../README.md``, ``anchors.md``; in backticks, code blocks
or plain text) must exist relative to the repository root or to the file. A bare name in capitals without a
folder (``TABLE.md``) is a placeholder and is not checked. No file may point into ``shared/``, which is not
part of the repository. Pure file reading: fast.
"""
from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = ("shared/docs", "../shared")

INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*(<[^>]*>|[^()\s]*(?:\([^()\s]*\)[^()\s]*)*)")
REFERENCE_LINK = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
URL = re.compile(r"\b(?:https?|ftp)://\S+|\bmailto:\S+|\bwww\.\S+")
MD_TOKEN = re.compile(r"(?<![\w./*{}<>$~%-])((?:\.{1,2}/)*[\w.-]*(?:/[\w.-]+)*\.md)(?![\w/-])")
FENCE = re.compile(r"^\s*(```|~~~)")


def doc_files(root: Path = ROOT) -> list[Path]:
    """The Markdown files whose links are checked."""
    files = [root / "README.md", root / "datasets" / "README.md", *sorted((root / "docs").glob("**/*.md"))]
    return [f for f in files if f.is_file()]


def _is_external(target: str) -> bool:
    return bool(re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target)) or target.startswith("//")


def _exists(candidates: list[Path], root: Path) -> bool:
    """True when one candidate exists and stays inside the repository."""
    for c in candidates:
        try:
            c.resolve().relative_to(root.resolve())
        except ValueError:
            continue
        if c.exists():
            return True
    return False


def check_file(path: Path, root: Path = ROOT) -> list[str]:
    """Problems of one Markdown file, each as ``file:line: message``."""
    problems: list[str] = []
    rel = path.relative_to(root) if path.is_relative_to(root) else path
    in_fence = False
    for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        where = f"{rel}:{lineno}"
        for bad in FORBIDDEN:
            if bad in line:
                problems.append(f"{where}: mentions {bad!r}, which is not part of the repository")
        if FENCE.match(line):
            in_fence = not in_fence
            links = []
        elif in_fence:
            links = []
        else:
            links = [m.group(1) for m in INLINE_LINK.finditer(line)]
            links += [m.group(1) for m in REFERENCE_LINK.finditer(line)]
        link_targets = set()
        for raw in links:
            target = raw.strip("<>").strip()
            if not target or target.startswith("#") or _is_external(target):
                continue
            target = unquote(target.split("#", 1)[0].split("?", 1)[0])
            link_targets.add(target)
            if not _exists([path.parent / target], root):
                problems.append(f"{where}: link target {target!r} does not exist (relative to {rel})")
        for m in MD_TOKEN.finditer(URL.sub(" ", line)):
            token = m.group(1)
            if token in link_targets:
                continue  # already checked as a link, relative to the file
            name = token.rsplit("/", 1)[-1]
            if "/" not in token and re.fullmatch(r"[A-Z0-9_]+\.md", name) and not _exists(
                    [root / token, path.parent / token], root):
                continue  # a placeholder such as TABLE.md
            if not _exists([root / token, path.parent / token], root):
                problems.append(f"{where}: names {token!r}, which does not exist "
                                f"(neither relative to the repository root nor to {rel})")
    return problems


def check_files(files: list[Path], root: Path = ROOT) -> list[str]:
    return [p for f in files for p in check_file(f, root)]


def test_docs_links_and_md_names_exist():
    files = doc_files()
    assert any(f.name == "README.md" and f.parent == ROOT for f in files)
    problems = check_files(files)
    assert not problems, "broken documentation references:\n" + "\n".join(problems)


def test_checker_reports_a_broken_link(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "good.md").write_text("# good\n", encoding="utf-8")
    page = tmp_path / "docs" / "page.md"
    page.write_text(
        "# page\n"
        "A [good link](good.md#top), an [external](https://example.com/x.md) and an [anchor](#page).\n"
        "Also `docs/good.md` by name.\n"
        "A [broken link](missing/nothing.md) and ![a missing image](img/none.png).\n"
        "```bash\n"
        "echo not-a-link [x](nowhere.txt) but a name: docs/gone.md\n"
        "```\n"
        "It mentions shared/docs/formats.md.\n",
        encoding="utf-8",
    )
    problems = check_file(page, tmp_path)
    text = "\n".join(problems)
    assert "docs/page.md:4: link target 'missing/nothing.md'" in text
    assert "docs/page.md:4: link target 'img/none.png'" in text
    assert "docs/page.md:6: names 'docs/gone.md'" in text
    assert "docs/page.md:8: mentions 'shared/docs'" in text
    assert "docs/page.md:8: names 'shared/docs/formats.md'" in text
    assert not any(":2:" in p or ":3:" in p for p in problems), problems
    assert len(problems) == 5, problems
