"""A receiver is a plug-in: outside its own package nothing names it or tests which it is.

The sources of ``simcore/`` and ``app/`` are read (their syntax trees: docstrings and comments are
documentation, not code) for three things, each outside ``simcore/receivers/<kind>/``:

- a string that is a receiver's kind (``"gm_apd"``);
- a comparison that tests a receiver's kind (``receiver.kind == ...``, ``receiver_kind != ...``,
  ``kind in (...)``): the declaration says what differs, the registry finds it;
- an import of a receiver's own modules (``simcore.receivers.gm_apd.frame``).

What remains is listed in ``ALLOWED`` with its reason: the registry naming its built-in
receivers, and code that is a receiver's by nature (the paper's reproduction is the LM-APD's).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from simcore import receivers

ROOT = Path(__file__).resolve().parent.parent
KINDS = tuple(receivers.BUILT_IN)

# file -> why it may name a receiver (each entry is checked to be still needed)
ALLOWED = {
    # the registry: the one list of the built-in kinds and where each declares itself
    "simcore/plugins/registry.py": "the registry's list of built-in receivers",
    # the paper's reproduction and its figures are the LM-APD's (Eqs. 7-31) by definition
    "simcore/reproduce.py": "the paper's reproduction: the LM-APD's timing figures",
    "simcore/cli/reproduce/items_echo.py": "the paper's reproduction: the LM-APD's chain",
    # issue 41's bench times Geiger mode's runs against linear mode's by definition
    "simcore/cli/bench/gm.py": "lmapd bench --gm: the Geiger-mode wall times",
    # the key reference's doc line of receiver.kind names the built-in kinds (documentation)
    "simcore/scene/sections.py": "the doc of the key receiver.kind",
    # lesson data: scenes a lesson sets up (documented data)
    "app/logic/lessons.py": "lesson data: the scene each lesson sets",
}


def sources() -> list[Path]:
    return sorted(p for d in ("simcore", "app") for p in (ROOT / d).rglob("*.py"))


def own_package(path: Path) -> str | None:
    """The kind whose package holds ``path`` (None: no receiver's)."""
    parts = path.relative_to(ROOT).parts
    if parts[:2] == ("simcore", "receivers") and len(parts) > 3 and parts[2] in KINDS:
        return parts[2]
    return None


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                found.add(id(body[0].value))
    return found


# what else has a kind: the trajectory's (``scene.trajectory.kind``, ``tr.kind`` for ``tr =
# scene.trajectory``, a fly-around result's ``self.kind``, which is its trajectory's)
TRAJECTORY_NAMES = ("trajectory", "tr")
TRAJECTORY_FILES = ("simcore/flyaround.py", "simcore/trajectory.py")


def _is_trajectory(node: ast.AST) -> bool:
    """Whether ``node`` is a trajectory section: ``x.trajectory``, ``trajectory`` or ``tr``."""
    if isinstance(node, ast.Attribute):
        return node.attr == "trajectory"
    return isinstance(node, ast.Name) and node.id in TRAJECTORY_NAMES


def _names_kind(node: ast.AST, path: Path | None = None) -> bool:
    """Whether ``node`` reads a receiver kind: ``x.kind``, ``receiver_kind``, ``x.receiver_kind``
    or ``["receiver_kind"]``; not a trajectory's kind (``scene.trajectory.kind``, ``tr.kind``,
    and a fly-around result's ``self.kind`` in the trajectory's own modules)."""
    if isinstance(node, ast.Attribute):
        if node.attr == "kind" and _is_trajectory(node.value):
            return False
        if node.attr == "kind" and isinstance(node.value, ast.Name) and node.value.id == "self":
            rel = str(path.relative_to(ROOT)) if path is not None else ""
            if rel in TRAJECTORY_FILES:
                return False
        return node.attr in ("kind", "receiver_kind")
    if isinstance(node, ast.Name):
        return node.id == "receiver_kind"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
        return any(isinstance(a, ast.Constant) and a.value == "receiver_kind" for a in node.args)
    if isinstance(node, ast.Subscript):
        return isinstance(node.slice, ast.Constant) and node.slice.value == "receiver_kind"
    return False


def _is_text(node: ast.AST) -> bool:
    """A string, or a tuple, list or set of strings: what a kind is tested against (comparing
    two kinds, ``kind != previous.kind``, tests no kind)."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        return any(_is_text(e) for e in node.elts)
    return False


def findings(path: Path, text: str) -> list[str]:
    """Where ``text`` (the source of ``path``) names a receiver or tests which one it is."""
    tree = ast.parse(text)
    docs = _docstrings(tree)
    own = own_package(path)
    found = []
    for node in ast.walk(tree):
        where = f"{path.relative_to(ROOT)}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            named = [k for k in KINDS if k != own and k in node.value]
            if named:
                found.append(f"{where}: the string {node.value[:60]!r} names {named[0]}")
        elif isinstance(node, ast.Compare):
            sides = (node.left, *node.comparators)
            if any(_names_kind(s, path) for s in sides) and any(_is_text(s) for s in sides):
                found.append(f"{where}: a comparison tests the receiver's kind")
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names = [a.name for a in node.names]
            module = getattr(node, "module", None) or ""
            for dotted in [module, *(f"{module}.{n}" for n in names)] if module else names:
                parts = dotted.split(".")
                if "receivers" in parts:
                    after = parts[parts.index("receivers") + 1 :]
                    if after and after[0] in KINDS and after[0] != own:
                        found.append(f"{where}: imports {dotted}")
                        break
            if node.__class__ is ast.ImportFrom and node.level and own is None:
                if set(names) & set(KINDS):
                    found.append(f"{where}: imports a receiver's package ({', '.join(names)})")
    return found


def test_the_check_finds_a_kind_test_a_kind_name_and_an_import():
    text = (
        '"""gm_apd in a docstring is documentation."""\n'
        "from simcore.receivers.gm_apd import frame\n"
        "def f(scene, summary):\n"
        '    """lm_apd here too."""\n'
        '    if scene.receiver.kind == "x":\n'
        "        return 1\n"
        '    if summary.get("receiver_kind") != "y":\n'
        "        return 2\n"
        "    if scene.receiver.kind != summary.receiver_kind:  # a change, not a kind\n"
        "        return 3\n"
        '    if scene.receiver.kind in ("a", "b"):\n'
        "        return 4\n"
        '    return "gm_apd"\n'
    )
    found = findings(ROOT / "app" / "example.py", text)
    assert len(found) == 5, found
    assert any("imports simcore.receivers.gm_apd" in f for f in found)
    assert sum("comparison" in f for f in found) == 3
    assert any("names gm_apd" in f for f in found)
    # a trajectory's kind is not a receiver's; a receiver's on anything else still is
    trajectory = (
        "def g(scene, tr, self):\n"
        '    if scene.trajectory.kind == "orbit" or tr.kind == "hold":\n'
        "        return 1\n"
        '    return self.kind == "approach"\n'
    )
    assert findings(ROOT / "simcore" / "flyaround.py", trajectory) == []
    assert len(findings(ROOT / "app" / "example.py", trajectory)) == 1  # self.kind elsewhere
    # inside its own package a receiver names itself freely
    own = ROOT / "simcore" / "receivers" / "gm_apd" / "x.py"
    assert findings(own, 'KIND = "gm_apd"\nfrom simcore.receivers.gm_apd import frame\n') == []


def test_no_source_outside_a_receivers_package_names_it_or_tests_its_kind():
    found = []
    for path in sources():
        rel = str(path.relative_to(ROOT))
        if rel in ALLOWED:
            continue
        found += findings(path, path.read_text(encoding="utf-8"))
    assert found == []


@pytest.mark.parametrize("rel", sorted(ALLOWED))
def test_every_allowed_file_still_needs_its_exception(rel):
    path = ROOT / rel
    if not path.exists():
        pytest.fail(f"{rel} is gone: drop it from ALLOWED")
    assert findings(path, path.read_text(encoding="utf-8")), f"{rel} no longer needs ALLOWED"
