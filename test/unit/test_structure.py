"""The repository's shape, checked from the source text (ast; nothing is imported, so this is cheap).

- every module of `humanoid_planner/core/` has its mirrored test file
  (`core/<stage>/<module>.py` -> `test/unit/core/<stage>/test_<module>.py`), and every test file there
  names the module it tests (`test_<module>.py`, or `test_<module>_<topic>.py` for more of them);
- every folder under `test/unit/` is a package, so equal test file names in two folders do not clash;
- every folder of `humanoid_planner/` holding Python files is a package (has an `__init__.py`): a build
  (wheel, colcon without --symlink-install) installs only the folders setuptools finds as packages;
- no module of the package, the benchmarks or the scripts imports a private name (`from x import _y`,
  or `x._y` on an imported module) of another of the project's modules;
- no module of the package, the benchmarks or the scripts reads a private attribute of another module's
  object (`obj._name` where obj is not self / cls and no code of the same module defines `_name`): a
  private name is its module's to change; the rare reach into a library's internals says why on its
  line with `# noqa: SLF001` (ruff's code for this rule);
- there is no import cycle among `humanoid_planner` modules (imports inside functions count too:
  a lazy import hides a circle, it does not remove it);
- no module of `humanoid_planner/core/` imports rclpy or a ROS message package (the core runs without ROS);
- no source file cites a document outside the repository (the contract the code relies on is in docs/
  and README.md);
- no constructor (`__init__`) of the core takes more than MAX_INIT_PARAMETERS parameters: a problem or
  options object carries the rest (value types made by @dataclass are records, not constructors);
- no function of `pipeline/` defines another function inside it: state shared by closures belongs to
  an object that owns it;
- every module-level UPPER_CASE constant of the core whose value is written as numbers (a tuning value
  or a tolerance) has a comment or docstring beside it (same line, the line above, or a docstring right
  after): it is either a PlannerOptions field or fixed, and then the comment says why that value.
"""
from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "humanoid_planner"
CORE = PACKAGE / "core"
UNIT = REPO / "test" / "unit"
PROJECT_TOPS = ("humanoid_planner", "preset_generation")
"""Top-level names of the project's importable code (`preset_generation` lives in scripts/)."""


def module_name(path: Path, root: Path) -> str:
    """Dotted name of a source file below `root` (a package's __init__ is the package)."""
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def package_modules() -> dict[str, Path]:
    return {module_name(p, REPO): p for p in PACKAGE.rglob("*.py")}


def imported_from(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    """The absolute module a `from ... import` statement reads from."""
    if not node.level:
        return node.module or ""
    base = importer.split(".") if is_package else importer.split(".")[:-1]
    base = base[:len(base) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the package modules it imports (a name imported from a package counts as its
    submodule when one exists, else as the package)."""
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name in modules)
            elif isinstance(node, ast.ImportFrom):
                source = imported_from(node, name, path.name == "__init__.py")
                for a in node.names:
                    if f"{source}.{a.name}" in modules:
                        deps.add(f"{source}.{a.name}")
                    elif source in modules:
                        deps.add(source)
        deps.discard(name)
        graph[name] = deps
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
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
                        found.append(sorted(comp))
    return found


def is_project_module(dotted: str) -> bool:
    """Whether a dotted name is a module file of the project (package or scripts/)."""
    rel = dotted.replace(".", "/")
    return any((base / f"{rel}.py").is_file() or (base / rel / "__init__.py").is_file()
               for base in (REPO, REPO / "scripts"))


def private_reach_ins(path: Path, importer: str, siblings: set[str]) -> list[str]:
    """`from x import _y` and `x._y` (x an imported project module) in one file; `siblings` are the
    names of modules beside it (the benchmarks import each other by bare name)."""
    def ours(module: str) -> bool:
        return module.split(".")[0] in PROJECT_TOPS or module in siblings

    where = path.relative_to(REPO) if path.is_relative_to(REPO) else path.name
    tree = ast.parse(path.read_text(), str(path))
    modules: set[str] = set()  # local names bound to project modules
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            modules.update((a.asname or a.name.split(".")[0]) for a in node.names if ours(a.name))
        elif isinstance(node, ast.ImportFrom):
            source = imported_from(node, importer, path.name == "__init__.py")
            if not ours(source):
                continue
            for a in node.names:
                if is_private(a.name):
                    found.append(f"{where}:{node.lineno}: from {source} import {a.name}")
                elif is_project_module(f"{source}.{a.name}"):
                    modules.add(a.asname or a.name)
    found += [f"{where}:{node.lineno}: {node.value.id}.{node.attr}" for node in ast.walk(tree)
              if isinstance(node, ast.Attribute) and is_private(node.attr) and isinstance(node.value, ast.Name)
              and node.value.id in modules]
    return found


PRIVATE_OWNERS = ("self", "cls")
EXEMPT_MARK = "noqa: SLF001"
"""A line reaching into a library's private attribute on purpose carries this, with the reason."""


def own_private_names(tree: ast.Module) -> set[str]:
    """Private names a module defines: functions, classes and methods, names and attributes it assigns
    (`self._x = ...`, `_y = ...`, annotated fields), and strings in its `__slots__`."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            out.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            out.add(node.attr)
        elif isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__slots__" for t in node.targets):
            out.update(c.value for c in ast.walk(node.value) if isinstance(c, ast.Constant) and isinstance(c.value, str))
    return {n for n in out if is_private(n)}


def foreign_private_reads(path: Path, root: Path = REPO) -> list[str]:
    """`file:line: expr` for every `x._name` whose `_name` the module does not define itself, x not self / cls,
    unless the line carries EXEMPT_MARK."""
    text = path.read_text()
    tree = ast.parse(text, str(path))
    own, lines = own_private_names(tree), text.splitlines()
    hits = sorted((node.lineno, node.col_offset, ast.unparse(node)) for node in ast.walk(tree)
                  if isinstance(node, ast.Attribute) and is_private(node.attr) and node.attr not in own
                  and not (isinstance(node.value, ast.Name) and node.value.id in PRIVATE_OWNERS)
                  and EXEMPT_MARK not in lines[node.lineno - 1])
    return [f"{path.relative_to(root)}:{line}: {expr}" for line, _, expr in hits]


# ----------------------------------------------------------------------------------------- tests
def test_every_core_module_has_its_mirrored_test_file():
    modules = sorted(p for p in CORE.rglob("*.py") if p.name != "__init__.py")
    assert len(modules) > 20  # the walk found the core
    missing = [str(p.relative_to(REPO)) for p in modules
               if not (UNIT / "core" / p.relative_to(CORE).parent / f"test_{p.name}").is_file()]
    assert not missing, f"core modules without test/unit/core/<stage>/test_<module>.py: {missing}"


def test_every_core_test_file_names_the_module_it_tests():
    """test/unit/core/<stage>/test_<module>.py or test_<module>_<topic>.py, <module> in that stage."""
    modules = {p.relative_to(CORE).with_suffix("") for p in CORE.rglob("*.py") if p.name != "__init__.py"}
    tests = sorted((UNIT / "core").rglob("test_*.py"))
    assert len(tests) >= len(modules)
    stray = [str(t.relative_to(REPO)) for t in tests
             if not any(m.parent == t.parent.relative_to(UNIT / "core")
                        and (t.stem == f"test_{m.name}" or t.stem.startswith(f"test_{m.name}_")) for m in modules)]
    assert not stray, f"name these test_<module>.py or test_<module>_<topic>.py beside their module's tests: {stray}"


def test_every_unit_test_folder_is_a_package():
    folders = [d for d in [UNIT, *UNIT.rglob("*")] if d.is_dir() and d.name != "__pycache__"
               and any(d.glob("test_*.py"))]
    assert len(folders) > 5
    missing = [str(d.relative_to(REPO)) for d in folders if not (d / "__init__.py").is_file()]
    assert not missing, f"add an __init__.py (same-named test files would clash): {missing}"


def folders_without_init(root: Path) -> list[Path]:
    """Folders below `root` (itself included) that hold .py files but no __init__.py."""
    return sorted(d for d in [root, *root.rglob("*")] if d.is_dir() and d.name != "__pycache__"
                  and any(d.glob("*.py")) and not (d / "__init__.py").is_file())


def test_every_package_folder_has_an_init():
    assert len(package_modules()) > 30  # the walk found the package
    missing = [str(d.relative_to(REPO)) for d in folders_without_init(PACKAGE)]
    assert not missing, f"add an __init__.py (a built wheel or colcon install leaves these out): {missing}"


def assert_none_found(finder, files, advice: str) -> None:
    """Fail with every finding of `finder` (path → list of "file:line: what") over `files`, under the advice."""
    found = [hit for p in files for hit in finder(p)]
    assert not found, advice + ":\n" + "\n".join(found)


def test_no_private_name_is_imported_across_modules():
    found = []
    for top in ("humanoid_planner", "benchmarks", "scripts"):
        for path in sorted((REPO / top).rglob("*.py")):
            importer = module_name(path, REPO / "scripts" if top == "scripts" else REPO)
            siblings = {p.stem for p in path.parent.glob("*.py")} if top != "humanoid_planner" else set()
            found += private_reach_ins(path, importer, siblings)
    assert not found, "private names used outside their module:\n" + "\n".join(found)


def test_no_private_attribute_of_another_modules_object_is_read():
    files = [p for top in ("humanoid_planner", "benchmarks", "scripts") for p in sorted((REPO / top).rglob("*.py"))]
    assert len(files) > 50
    assert_none_found(foreign_private_reads, files, "use (or add) a public name of the object's module")


def test_no_import_cycle_among_package_modules():
    graph = import_graph(package_modules())
    assert len(graph) > 30 and any(graph.values())  # the graph was built
    assert not cycles(graph), f"import cycles: {cycles(graph)}"


ROS_TOPS = ("rclpy", "rcl_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "shape_msgs", "trajectory_msgs",
            "visualization_msgs", "builtin_interfaces", "action_msgs", "humanoid_planner_interfaces")
OUTSIDE_DOCS = ("DESIGN §", "DESIGN.md", "shared/research", "shared/seeds", "../shared")
"""How a citation of the product's planning documents (not in this repository) reads."""


def ros_imports(path: Path, root: Path = REPO) -> list[str]:
    """`file:line: module` of every import of a ROS package in a source file."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
        out += [f"{path.relative_to(root)}:{node.lineno}: {n}" for n in names if n.split(".")[0] in ROS_TOPS]
    return out


def outside_citations(path: Path, root: Path = REPO) -> list[str]:
    return [f"{path.relative_to(root)}:{k}: {line.strip()}" for k, line in enumerate(path.read_text().splitlines(), 1)
            if any(c in line for c in OUTSIDE_DOCS)]


def test_core_never_imports_ros():
    assert_none_found(ros_imports, sorted(CORE.rglob("*.py")), "the core must run without ROS")


def test_no_source_cites_a_document_outside_the_repository():
    files = [p for top in ("humanoid_planner", "test", "benchmarks", "scripts", "docs") for p in (REPO / top).rglob("*")
             if p.suffix in (".py", ".md", ".yaml") and p.is_file() and p != Path(__file__)]
    files += [REPO / "README.md", REPO / "Makefile"]
    assert len(files) > 50
    assert_none_found(outside_citations, files, "cite README.md or docs/ instead")


# ---------------------------------------------------------------------------- the checks themselves
def test_ros_import_and_citation_finders_see_what_they_should(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("import numpy\nimport rclpy.node\nfrom sensor_msgs.msg import JointState\n"
                   "from .x import y\n# see DESIGN §4\n")
    assert [h.split(": ")[1] for h in ros_imports(src, tmp_path)] == ["rclpy.node", "sensor_msgs.msg"]
    assert [h.split(":")[1] for h in outside_citations(src, tmp_path)] == ["5"]


def test_cycle_finder_and_reach_in_finder_see_what_they_should(tmp_path):
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    src = tmp_path / "m.py"
    src.write_text("from humanoid_planner.core.postprocess import timing\n"
                   "from humanoid_planner.core.transforms import _helper, invert\n"
                   "from numpy import _core\n"
                   "x = timing._BlendedPath\n")
    found = private_reach_ins(src, "m", set())
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "sub" / "mod.py").write_text("")
    (tmp_path / "pkg" / "data").mkdir()  # no .py files: not a package, nothing to install as code
    assert folders_without_init(tmp_path / "pkg") == [tmp_path / "pkg" / "sub"]
    assert [f.split(": ", 1)[1] for f in found] == [
        "from humanoid_planner.core.transforms import _helper", "timing._BlendedPath"]


def test_foreign_private_read_finder_sees_what_it_should(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("class A:\n    __slots__ = ('_s',)\n    def __init__(self, other):\n        self._x = 1\n"
                   "        self._y = other._x + other._s  # own names: fine\n"
                   "    def _own(self):\n        return self._y + self.z._w\n"
                   "def f(a, checker):\n    a._own()\n    cls = a\n    return checker.levels._units, checker._fk(1)\n"
                   "import os\nos._exit(0)  # noqa: SLF001 - skip the teardown\nos._exit(1)\n")
    assert [h.split(": ", 1)[1] for h in foreign_private_reads(src, tmp_path)] == [
        "self.z._w", "checker.levels._units", "checker._fk", "os._exit"]


# ---------------------------------------------------------------------------------- core shape
MAX_INIT_PARAMETERS = 6


def wide_inits(path: Path, root: Path = REPO) -> list[str]:
    """`file:line: Class(n)` for every __init__ taking more than MAX_INIT_PARAMETERS parameters (self excluded)."""
    out = []
    for cls in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(cls, ast.ClassDef):
            continue
        for f in cls.body:
            if isinstance(f, ast.FunctionDef) and f.name == "__init__":
                a = f.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) - 1 + (a.vararg is not None) + (a.kwarg is not None)
                if n > MAX_INIT_PARAMETERS:
                    out.append(f"{path.relative_to(root)}:{f.lineno}: {cls.name}({n})")
    return out


def nested_defs(path: Path, root: Path = REPO) -> list[str]:
    """`file:line: outer.inner` for every function defined inside another function."""
    out = []
    for outer in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(outer, (ast.FunctionDef, ast.AsyncFunctionDef)):
            out += [f"{path.relative_to(root)}:{inner.lineno}: {outer.name}.{inner.name}" for inner in ast.walk(outer)
                    if inner is not outer and isinstance(inner, (ast.FunctionDef, ast.AsyncFunctionDef))]
    return out


def test_no_core_constructor_takes_more_than_six_parameters():
    assert_none_found(wide_inits, sorted(CORE.rglob("*.py")), "pass a problem or options object instead")


def test_no_function_in_the_pipeline_defines_another():
    assert_none_found(nested_defs, sorted((CORE / "pipeline").rglob("*.py")), "give the shared state an owner (a class and its methods)")


def test_constructor_and_nested_def_finders_see_what_they_should(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("class A:\n    def __init__(self, a, b, c, d, e, f, *, g=1):\n        pass\n"
                   "class B:\n    def __init__(self, a, b, c, d, e, f):\n        pass\n"
                   "def outer():\n    def inner():\n        pass\n    return lambda: 1\n")
    assert [h.split(": ")[1] for h in wide_inits(src, tmp_path)] == ["A(7)"]
    assert [h.split(": ")[1] for h in nested_defs(src, tmp_path)] == ["outer.inner"]


# ------------------------------------------------------------------------------- tuning constants
def is_number_literal(node: ast.expr) -> bool:
    """A value written as numbers: 0.25, -1e9, 64 * 2**20, (0.0, 0.05) — not one computed from names."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, ast.UnaryOp):
        return is_number_literal(node.operand)
    if isinstance(node, ast.BinOp):
        return is_number_literal(node.left) and is_number_literal(node.right)
    if isinstance(node, ast.Tuple):
        return bool(node.elts) and all(is_number_literal(e) for e in node.elts)
    return False


def undocumented_constants(path: Path, root: Path = REPO) -> list[str]:
    """`file:line: NAME` of module-level UPPER_CASE number constants with no comment on their lines or the
    line above, and no docstring right after."""
    text = path.read_text()
    lines, body = text.splitlines(), ast.parse(text, str(path)).body
    out = []
    for k, node in enumerate(body):
        if not isinstance(node, (ast.Assign, ast.AnnAssign)) or node.value is None or not is_number_literal(node.value):
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        names = [t.id for t in targets if isinstance(t, ast.Name) and t.id.lstrip("_")[:1].isupper() and t.id.upper() == t.id]
        if not names:
            continue
        commented = any("#" in lines[i] for i in range(node.lineno - 1, node.end_lineno))
        above = node.lineno >= 2 and lines[node.lineno - 2].lstrip().startswith("#")
        after = body[k + 1] if k + 1 < len(body) else None
        docstring = isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)
        if not (commented or above or docstring):
            out.append(f"{path.relative_to(root)}:{node.lineno}: {names[0]}")
    return out


def test_every_core_number_constant_says_why_beside_it():
    files = sorted(CORE.rglob("*.py"))
    assert sum(len(undocumented_constants(p)) == 0 for p in files) > 20
    assert_none_found(undocumented_constants, files, "say why that value beside it (or make it a PlannerOptions field)")


def test_constant_finder_sees_what_it_should(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("A = 1\nB = 2  # why\n# why\nC = (0.1, -2)\nD = 64 * 2**20\n\"\"\"why\"\"\"\nE = A + 1\n"
                   "F = 'text'\n_G = 1e-9\nlower = 3\nH: float = 0.5\ndef f():\n    I = 1\n")
    assert [h.split(": ")[1] for h in undocumented_constants(src, tmp_path)] == ["A", "_G", "H"]
