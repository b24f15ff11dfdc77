"""The package's structure rules: no import cycles, small functions and modules, named offsets
and named fields, and the thesis a study on top of the library.

These read the source with :mod:`ast`; they do not import the package (but for one check of
what importing the command line imports, made in another process).
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "nlcx"
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 600
#: Packed parameter, state and log blocks: read through named offsets (nlcx.layout), never ``o + 6``.
PACKED_ARRAYS = {"p", "cp", "cs", "cs0", "sp", "ep", "es", "es0", "log", "LOG"}
#: The names the kernel, the engine and the plugins give the kernel's named structures
#: (nlcx.kernel.structures and the kernel's own work spaces), the engine's (a tableau, a metric
#: block, a kernel call) and the positional tuples they replaced (``control``, ``state``,
#: ``one_path``, ``frictional``), and the packed state of the friction modes.
STRUCTURES = {
    "integration", "tableau", "plant", "controller", "control", "elements", "forces", "records", "outcome",
    "friction_path", "frictional", "slots", "signals", "stages", "flat", "work", "scratch", "one", "one_path",
    "state", "modes", "block", "call",
}  # fmt: skip
#: Where values are structures read by name: the kernel, the engine and the plugins.
NAMED_FIELD_PACKAGES = ("kernel", "engine", "plants", "controllers", "uncertainty", "references")
#: The thesis: a study built on the library, which nothing outside it imports.
THESIS = "nlcx.thesis"
#: The one module outside the thesis that names its modules: the command line's table of the
#: thesis's commands, each imported when it is used.
THESIS_COMMAND_TABLE = "nlcx.cli.lazy"


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _generated(path: Path) -> bool:
    return "generated" in path.relative_to(PACKAGE).parts


def _imports(name: str, path: Path, known: set[str], source: str | None = None) -> set[str]:
    """Every nlcx module ``name`` imports, at module level or inside a function (``source``:
    its text, default read from ``path``)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text() if source is None else source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([node.module] if node.module else []))
            # ``from nlcx import registry`` imports the module nlcx.registry; only a name that is
            # not a module (``from nlcx import __version__``) is an import of the package itself
            submodules = {f"{base}.{alias.name}" for alias in node.names} & known
            found.update(submodules)
            if len(submodules) < len(node.names):
                found.add(base)
    return {m for m in found if m in known and m != name}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles_counting_imports_inside_functions() -> None:
    mods = _modules()
    graph = {name: _imports(name, path, set(mods)) for name, path in mods.items()}
    assert graph["nlcx.engine"], "the import graph must see nlcx's own imports"
    assert _cycles(graph) == []


def _docstring_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines of the function's docstring (0 without one)."""
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        return first.end_lineno - first.lineno + 1
    return 0


def test_no_function_longer_than_80_lines() -> None:
    """80 lines of code: the docstring (its examples included) does not count."""
    long = []
    for path in _modules().values():
        if _generated(path):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = node.end_lineno - node.lineno + 1 - _docstring_lines(node)
                if length > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({length} lines)")
    assert long == []


def _numeric_literals(node: ast.AST) -> list[ast.Constant]:
    """Numeric constants in ``node``, except inside ``a.shape[...]`` (a size, not an offset)."""
    if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Attribute) and node.value.attr == "shape":
        return []
    if isinstance(node, ast.Constant):
        return [node] if type(node.value) in (int, float) else []
    return [hit for child in ast.iter_child_nodes(node) for hit in _numeric_literals(child)]


def _bare_offsets(source: str) -> list[str]:
    """Subscripts of a packed array whose index holds a numeric literal (``cp[row, h + 12]``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        packed = isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in PACKED_ARRAYS
        if packed and _numeric_literals(node.slice):
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_offset_checker_flags_a_literal() -> None:
    source = "v = cp[row, o + 6]\nw = cp[row, o + L.kp]\nz = p[_row(p.shape[0], v)]\n"
    assert _bare_offsets(source) == ["1: cp[row, o + 6]"]


def test_no_bare_numeric_offsets_into_packed_arrays() -> None:
    found = []
    for path in _modules().values():
        if not _generated(path):
            found += [f"{path.relative_to(PACKAGE.parent)}:{hit}" for hit in _bare_offsets(path.read_text())]
    assert found == []


def _is_position(node: ast.expr) -> bool:
    """Whether ``node`` is an integer literal (``3``, ``-1``): a position, not a name."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        node = node.operand
    return isinstance(node, ast.Constant) and type(node.value) is int


def _positional_reads(source: str) -> list[str]:
    """Subscripts of a structure (a name of :data:`STRUCTURES`, bare or as an attribute,
    ``scratch[9]``, ``self.records[3]``) whose index is an integer literal or holds one as an
    element (``state[0][b]``, ``forces[..., 2]``): a field read by its position. Offsets into
    packed arrays are :func:`_bare_offsets`' business; slices and computed indices pass."""
    found: list[tuple[int, int, str]] = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Subscript):
            continue
        value = node.value
        name = value.id if isinstance(value, ast.Name) else value.attr if isinstance(value, ast.Attribute) else None
        index = node.slice.elts if isinstance(node.slice, ast.Tuple) else [node.slice]
        if name in STRUCTURES and any(_is_position(i) for i in index):
            found.append((node.lineno, node.col_offset, ast.unparse(node)))
    return [f"{line}: {text}" for line, _, text in sorted(found)]


def test_positional_read_checker_flags_literal_positions_only() -> None:
    source = (
        "a = scratch[9]\nb = self.records[3]\nc = state[0][b]\nd = forces[..., 2]\ne = slots.x[i, 0]\n"
        "f = scratch.one\ng = stages[j]\nh = plant[1:]\nk = rows[0]\nm = outcome[-1]\n"
    )
    assert _positional_reads(source) == [
        "1: scratch[9]", "2: self.records[3]", "3: state[0]", "4: forces[..., 2]", "10: outcome[-1]",
    ]  # fmt: skip


def test_structures_are_read_by_name_in_the_kernel_engine_and_plugins() -> None:
    found = []
    for path in _modules().values():
        if path.relative_to(PACKAGE).parts[0] in NAMED_FIELD_PACKAGES and not _generated(path):
            found += [f"{path.relative_to(PACKAGE.parent)}:{hit}" for hit in _positional_reads(path.read_text())]
    assert found == []


def _too_long(source: str) -> int | None:
    """The number of lines of a module over :data:`MAX_MODULE_LINES`, else None."""
    lines = len(source.splitlines())
    return lines if lines > MAX_MODULE_LINES else None


def test_module_length_checker_flags_a_long_module() -> None:
    assert _too_long("x = 1\n" * MAX_MODULE_LINES) is None
    assert _too_long("x = 1\n" * (MAX_MODULE_LINES + 1)) == MAX_MODULE_LINES + 1


def test_no_module_longer_than_600_lines() -> None:
    """Every module of nlcx (generated code aside) has at most 600 lines, its docstrings included."""
    long = {}
    for path in _modules().values():
        if not _generated(path) and (lines := _too_long(path.read_text())):
            long[str(path.relative_to(PACKAGE.parent))] = lines
    assert long == {}


def _class_homes(sources: dict[str, str]) -> dict[str, list[str]]:
    """Each class name defined more than once, with where (``module:line``) it is defined."""
    homes: dict[str, list[str]] = {}
    for module, source in sources.items():
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.ClassDef):
                homes.setdefault(node.name, []).append(f"{module}:{node.lineno}")
    return {name: where for name, where in homes.items() if len(where) > 1}


def test_class_name_checker_flags_a_shared_name() -> None:
    assert _class_homes({"a": "class A: ...", "b": "class B: ..."}) == {}
    assert _class_homes({"a": "class A: ...", "b": "class A: ..."}) == {"A": ["a:1", "b:1"]}


def test_no_two_classes_share_a_name() -> None:
    """One class per name across nlcx: a name says which class it is wherever it is read."""
    sources = {name: path.read_text() for name, path in _modules().items()}
    assert _class_homes(sources) == {}


def _in_thesis(module: str) -> bool:
    return module == THESIS or module.startswith(THESIS + ".")


#: A module of the thesis named in a string: ``nlcx.thesis``, ``nlcx.thesis.cli:reproduce``.
_THESIS_NAME = re.compile(r"\bnlcx\.thesis(?![\w])")
#: Calls that import the module their first argument names.
_IMPORTING_CALLS = {"import_module", "__import__"}


def _documentation(tree: ast.Module) -> set[int]:
    """The ids of the string constants that only document (a docstring, a bare string statement)."""
    return {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)
    }


def _thesis_references(name: str, path: Path, source: str, known: set[str]) -> list[str]:
    """Where module ``name`` reaches for the thesis: an import of ``nlcx.thesis`` or a module under
    it (absolute or relative, at module level or in a function), a call of
    ``importlib.import_module`` or ``__import__`` with a literal name under it, and any other
    string that names one (``"nlcx.thesis.cli:reproduce"``, as an entry point does); docstrings
    aside."""
    tree = ast.parse(source)
    found = [f"imports {m}" for m in sorted(_imports(name, path, known | {THESIS}, source)) if _in_thesis(m)]
    documentation = _documentation(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and node.args:
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
            first = node.args[0]
            literal = isinstance(first, ast.Constant) and isinstance(first.value, str)
            if called in _IMPORTING_CALLS and literal and _in_thesis(first.value):
                found.append(f"{node.lineno}: {called}({first.value!r})")
                documentation.add(id(first))
        if (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in documentation
            and _THESIS_NAME.search(node.value)
        ):
            found.append(f"{node.lineno}: names {node.value!r}")
    return found


def test_thesis_reference_finder_finds_every_form() -> None:
    source = (
        '"""The docstring may name nlcx.thesis.cli."""\n'
        "import importlib\n"
        "import nlcx.thesis.catalog\n"
        "from nlcx import thesis, pages\n"
        "from ..thesis import profiles\n"
        "from nlcx.pages import render\n"
        "def f():\n"
        '    """Nor is nlcx.thesis here."""\n'
        "    from nlcx.thesis.reproduce import reproduce\n"
        '    importlib.import_module("nlcx.thesis.cli")\n'
        '    load("nlcx.thesis.cli:reproduce")\n'
        '    return "nlcx.thesisless", "nlcx.pages.run:PAGE"\n'
    )
    known = {"nlcx.cli.x", "nlcx.thesis.catalog", "nlcx.thesis.profiles", "nlcx.thesis.reproduce", "nlcx.pages",
             "nlcx.pages.render", "nlcx.thesis.cli"}  # fmt: skip
    found = _thesis_references("nlcx.cli.x", PACKAGE / "cli" / "x.py", source, known)
    assert found == [
        "imports nlcx.thesis", "imports nlcx.thesis.catalog", "imports nlcx.thesis.profiles",
        "imports nlcx.thesis.reproduce", "10: import_module('nlcx.thesis.cli')",
        "11: names 'nlcx.thesis.cli:reproduce'",
    ]  # fmt: skip


def test_nothing_outside_the_thesis_imports_it_but_the_command_table() -> None:
    """The thesis is a study on top of the library: no module outside nlcx/thesis imports it or
    names one of its modules, except the table of the thesis's commands, which names them."""
    mods = _modules()
    known = set(mods)
    found = {
        name: refs
        for name, path in mods.items()
        if not _in_thesis(name) and (refs := _thesis_references(name, path, path.read_text(), known))
    }
    table = found.pop(THESIS_COMMAND_TABLE, [])
    assert found == {}
    assert table and all("names 'nlcx.thesis.cli:" in ref for ref in table), table


def test_importing_the_command_line_or_listing_its_commands_leaves_the_thesis_unimported() -> None:
    code = (
        "import sys\n"
        "import nlcx.cli\n"
        "after_import = sorted(m for m in sys.modules if m == 'nlcx.thesis' or m.startswith('nlcx.thesis.'))\n"
        "sys.argv = ['nlcx', '--help']\n"
        "try:\n"
        "    nlcx.cli.main()\n"
        "except SystemExit:\n"
        "    pass\n"
        "after_help = sorted(m for m in sys.modules if m == 'nlcx.thesis' or m.startswith('nlcx.thesis.'))\n"
        "print('THESIS', after_import, after_help)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "reproduce" in proc.stdout and "identify" in proc.stdout, "nlcx --help lists the thesis's commands"
    assert proc.stdout.splitlines()[-1] == "THESIS [] []"
