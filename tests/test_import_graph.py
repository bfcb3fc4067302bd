"""The arrows between the project's modules run one way: no import circle anywhere (a module-level or a
function-level import both count; imports only for type checkers, under ``if TYPE_CHECKING:``, do not), and
``inference`` (the runtime library) imports no other project package."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("inference", "synth", "training", "labeler")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_names(module: str, is_package: bool, node: ast.Import | ast.ImportFrom) -> list[str]:
    """Absolute dotted names an import statement may refer to (``from a import b``: ``a`` and ``a.b``)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    base = node.module or ""
    if node.level:
        here = module.split(".") if is_package else module.split(".")[:-1]
        here = here[:len(here) - (node.level - 1)]
        base = ".".join(here + ([base] if base else []))
    return [base] + [f"{base}.{a.name}" for a in node.names]


def import_graph(files: dict[str, Path]) -> dict[str, set[str]]:
    """Module → the project modules it imports (the nearest existing module of each imported name)."""
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                       and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
        deps: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in typing_only:
                for target in imported_names(name, path.name == "__init__.py", node):
                    while target and target not in files:
                        target = target.rpartition(".")[0]
                    if target and target != name:
                        deps.add(target)
        graph[name] = deps
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def project_files() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def test_the_circle_finder_finds_a_circle(tmp_path):
    """The check itself: two modules that import each other (one inside a function) are a circle; a
    type-checking-only import is not."""
    a, b, c = (tmp_path / f"{n}.py" for n in "abc")
    a.write_text("import b\n")
    b.write_text("def f():\n    from a import x\n")
    c.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import a\nimport b\n")
    files = {"a": a, "b": b, "c": c}
    assert circles(import_graph(files)) == [["a", "b"]]
    b.write_text("X = 1\n")
    assert circles(import_graph(files)) == []


def test_no_import_circle_anywhere():
    found = circles(import_graph(project_files()))
    assert not found, "import circles (split the shared part out, or invert the dependency): " + "; ".join(
        " ↔ ".join(c) for c in found)


def test_the_runtime_library_imports_no_other_project_package():
    graph = import_graph(project_files())
    upward = sorted(f"{m} → {d}" for m, deps in graph.items() if m.split(".")[0] == "inference"
                    for d in deps if d.split(".")[0] != "inference")
    assert not upward, upward


#: what each room may import besides itself (docs/architecture.md): the runtime library nothing; the generator
#: (a product feature, ``rally3d synth``) the runtime library; training and the labeler build on both
ROOM_MAY_IMPORT = {"inference": set(), "synth": {"inference"}, "training": {"inference", "synth"},
                   "labeler": {"inference", "synth"}}


def test_every_room_imports_only_the_rooms_below_it():
    graph = import_graph(project_files())
    wrong = sorted(f"{m} → {d}" for m, deps in graph.items() for d in deps
                   if d.split(".")[0] != m.split(".")[0] and d.split(".")[0] not in ROOM_MAY_IMPORT[m.split(".")[0]])
    assert not wrong, "imports against the rooms' rule (docs/architecture.md): " + "; ".join(wrong)
