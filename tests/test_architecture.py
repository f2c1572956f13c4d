"""The shape of the code (docs/architecture.md): no import cycle, rooms import only the rooms they
may, no module over 500 lines, no class over 30 methods, no function over 60 lines, no block of
more than 10 lines written twice: anywhere in pnlviz/."""

import ast
import io
import keyword
import sys
import tokenize
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

from import_graph import cycles, import_graph, room_graph  # noqa: E402

#: what each room may import (besides itself), as docs/architecture.md draws it
ALLOWED = {
    "pnlviz": {"pnlviz.paths", "pnlviz.api", "pnlviz.detect"},
    "pnlviz.paths": set(),
    "pnlviz.conventions": set(),
    "pnlviz.errors": set(),
    "pnlviz.field": {"pnlviz.paths"},
    "pnlviz.geometry": {"pnlviz.field"},
    "pnlviz.data": {"pnlviz.conventions", "pnlviz.field"},
    "pnlviz.labels": {"pnlviz.field", "pnlviz.geometry", "pnlviz.data"},
    "pnlviz.metrics": {"pnlviz.conventions", "pnlviz.field", "pnlviz.geometry", "pnlviz.data"},
    "pnlviz.calib": {"pnlviz.conventions", "pnlviz.field", "pnlviz.geometry", "pnlviz.labels"},
    "pnlviz.synth": {"pnlviz.conventions", "pnlviz.field", "pnlviz.geometry", "pnlviz.data"},
    "pnlviz.detect": {"pnlviz.paths", "pnlviz.field", "pnlviz.geometry", "pnlviz.data", "pnlviz.labels",
                      "pnlviz.synth"},
    "pnlviz.viz": {"pnlviz.field", "pnlviz.geometry"},
    "pnlviz.api": {"pnlviz.field", "pnlviz.geometry", "pnlviz.data", "pnlviz.calib", "pnlviz.detect", "pnlviz.viz"},
    "pnlviz.pipeline": {"pnlviz.conventions", "pnlviz.field", "pnlviz.geometry", "pnlviz.data", "pnlviz.labels",
                        "pnlviz.calib", "pnlviz.metrics"},
    "pnlviz.app": {"pnlviz.conventions", "pnlviz.field", "pnlviz.geometry", "pnlviz.data", "pnlviz.calib",
                   "pnlviz.metrics", "pnlviz.viz", "pnlviz.pipeline"},  # not detect: the app never imports torch
    "pnlviz.commands": {"pnlviz", "pnlviz.paths", "pnlviz.conventions", "pnlviz.field", "pnlviz.geometry", "pnlviz.data",
                        "pnlviz.labels", "pnlviz.metrics", "pnlviz.calib", "pnlviz.synth", "pnlviz.detect",
                        "pnlviz.viz", "pnlviz.pipeline", "pnlviz.app"},
    "pnlviz.cli": {"pnlviz.commands"},
    "pnlviz.__main__": {"pnlviz.commands"},
}
MAX_MODULE_LINES = 500
MAX_CLASS_METHODS = 30
MAX_FUNCTION_LINES = 60
MAX_REPEATED_LINES = 10


def test_the_geometry_helpers_doctests_hold():
    import doctest

    import pnlviz.api
    import pnlviz.field.model
    import pnlviz.geometry.angles
    import pnlviz.geometry.camera
    import pnlviz.geometry.distance
    import pnlviz.geometry.homography
    import pnlviz.geometry.projection
    import pnlviz.geometry.so3

    for module in (pnlviz.api, pnlviz.field.model, pnlviz.geometry.angles, pnlviz.geometry.camera, pnlviz.geometry.so3, pnlviz.geometry.distance, pnlviz.geometry.homography,
                   pnlviz.geometry.projection):
        result = doctest.testmod(module)
        assert result.attempted > 0 and result.failed == 0, module.__name__


def test_the_import_graph_sees_lazy_imports():
    graph = import_graph()
    assert "pnlviz.commands.calibrate" in graph["pnlviz.commands"]
    assert "pnlviz.calib.frame" in graph["pnlviz.commands.calibrate"]  # imported inside a function there


def test_no_import_cycle_between_modules_or_rooms():
    graph = import_graph()
    assert cycles(graph) == []
    assert cycles(room_graph(graph)) == []


def test_rooms_import_only_what_they_may():
    rooms = room_graph(import_graph())
    assert set(rooms) == set(ALLOWED), "a room was added or removed: say what it may import"
    # the leaf of errors (ArgumentError) may be imported by every room
    extra = {r: sorted(deps - ALLOWED[r] - {"pnlviz.errors"}) for r, deps in rooms.items()
             if deps - ALLOWED[r] - {"pnlviz.errors"}}
    assert extra == {}


def _modules() -> list[Path]:
    return sorted((REPO / "pnlviz").rglob("*.py"))


def _functions(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def too_big(paths: list[Path], root: Path) -> list[str]:
    """Modules over :data:`MAX_MODULE_LINES` lines, classes with more than :data:`MAX_CLASS_METHODS`
    methods (every def in the class body) and functions over :data:`MAX_FUNCTION_LINES` lines
    (a nested function counts on its own and within its parent)."""
    found = []
    for path in paths:
        name, text = path.relative_to(root), path.read_text()
        if len(text.splitlines()) > MAX_MODULE_LINES:
            found.append(f"{name}: {len(text.splitlines())} lines")
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                n = sum(isinstance(b, (ast.FunctionDef, ast.AsyncFunctionDef)) for b in node.body)
                if n > MAX_CLASS_METHODS:
                    found.append(f"{name}:{node.lineno} class {node.name} ({n} methods)")
        for node in _functions(tree):
            n = node.end_lineno - node.lineno + 1
            if n > MAX_FUNCTION_LINES:
                found.append(f"{name}:{node.lineno} {node.name} ({n} lines)")
    return found


def test_the_size_check_finds_each_kind(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES - 1))  # with its def: 60 lines
    methods = "".join(f"    def m{i}(self):\n        return {i}\n" for i in range(MAX_CLASS_METHODS + 1))
    (tmp_path / "long.py").write_text(f"def f():\n{body}    return x0\n")
    (tmp_path / "wide.py").write_text(f"class C:\n{methods}")
    (tmp_path / "big.py").write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    (tmp_path / "ok.py").write_text(f"def g():\n{body}")
    found = too_big(sorted(tmp_path.glob("*.py")), tmp_path)
    assert sorted(f.split(":")[0] for f in found) == ["big.py", "long.py", "wide.py"], found


def test_no_module_class_or_function_too_big():
    """Anywhere in pnlviz/, the app and the commands included."""
    assert too_big(_modules(), REPO) == []


def _shapes(path: Path) -> list[tuple[int, str]]:
    """(line number, shape) of each code line: names, numbers and strings replaced by
    placeholders (keywords kept), comments, docstrings, blank lines and imports left out."""
    lines = defaultdict(list)
    docstrings = {n.body[0].lineno for n in ast.walk(ast.parse(path.read_text()))
                  if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
                  and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        if tok.type in (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
            continue
        if tok.type == tokenize.NAME and not keyword.iskeyword(tok.string):
            text = "N"
        elif tok.type == tokenize.NUMBER:
            text = "0"
        elif tok.type == tokenize.STRING:
            text = "S"
        else:
            text = tok.string
        lines[tok.start[0]].append(text)
    out = []
    for number, toks in sorted(lines.items()):
        shape = " ".join(toks)
        data_only = "N" not in toks and not any(t[:1].isalpha() or t[:1] == "_" for t in toks if t not in ("S", "0"))
        if number in docstrings or toks[0] in ("import", "from") or data_only:  # data (lists of names) is not code
            continue
        out.append((number, shape))
    return out


def repeated_blocks(paths, root: Path) -> list[str]:
    """Runs of 11 code lines of the same shape in two files (see :func:`_shapes`)."""
    seen, repeats = {}, []
    for path in paths:
        name = str(path.relative_to(root))
        shapes = _shapes(path)
        for i in range(len(shapes) - MAX_REPEATED_LINES):
            window = tuple(s for _, s in shapes[i:i + MAX_REPEATED_LINES + 1])
            if window in seen and not seen[window].startswith(f"{name}:"):
                repeats.append(f"{name}:{shapes[i][0]} ~ {seen[window]}")
            seen.setdefault(window, f"{name}:{shapes[i][0]}")
    return repeats


def test_the_repeated_block_check_finds_a_renamed_copy(tmp_path):
    def function(name: str, var: str) -> str:
        body = [f"    {var}{i} = {var}{i - 1} * {i} + len('{var}')" for i in range(1, 13)]
        return "\n".join([f"def {name}({var}0):", *body, f"    return {var}12", ""])

    (tmp_path / "a.py").write_text(function("f", "x"))
    (tmp_path / "b.py").write_text(function("g", "y"))  # the same shape with other names
    (tmp_path / "c.py").write_text("def h(z):\n" + "".join(f"    z = z + {i}\n" for i in range(5)))
    found = repeated_blocks(sorted(tmp_path.glob("*.py")), tmp_path)
    assert found and all(line.startswith("b.py:") and "a.py:" in line for line in found)


def test_no_block_of_more_than_10_lines_written_twice():
    """Runs of 11 code lines with the same shape (the same lines, or the same with other names,
    numbers and strings), anywhere in pnlviz/."""
    assert repeated_blocks(_modules(), REPO) == []


def test_each_vocabulary_is_written_once():
    """Review statuses, sources, provenances, failure codes and finding kinds are defined once
    (pnlviz/conventions.py, as Literal types and their tuples): no other module spells one of
    those tuples out again."""
    from pnlviz import conventions

    vocabularies = [conventions.REVIEW_STATES, conventions.SOURCES, conventions.PROVENANCES,
                    conventions.FAILURE_CODES, conventions.FINDING_KINDS, conventions.REVIEWED]
    found = []
    for path in _modules():
        if path.name == "conventions.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Tuple) and len(node.elts) >= 2 and all(
                    isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts):
                words = tuple(e.value for e in node.elts)
                if words in vocabularies:
                    found.append(f"{path.relative_to(REPO)}:{node.lineno} {words}")
    assert found == []
