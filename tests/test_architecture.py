"""The layout guard (docs/architecture.md): stages import only earlier stages, no import
cycles, matplotlib only in report/plotting/, typer only in cli/, no process-wide state
changed, no private names imported across modules, no module over 600 lines but those
listed with a reason."""

from __future__ import annotations

import ast
from pathlib import Path
from types import MappingProxyType

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "opticalstamp"
#: the stages in pipeline order: each may import itself and those before it
ORDER = (
    "validate",
    "units",
    "defaults",
    "device",
    "design",
    "io",
    "raytrace",
    "analysis",
    "imaging",
    "studies",
    "report",
    "cli",
)


def _modules():
    for py in sorted(SRC.rglob("*.py")):
        rel = py.relative_to(SRC).with_suffix("")
        parts = rel.parts[:-1] if rel.parts[-1] == "__init__" else rel.parts
        yield ".".join(parts) or "__init__", py, ast.parse(py.read_text())


def _package(module: str, py: Path) -> list[str]:
    parts = module.split(".") if module != "__init__" else []
    return parts if py.name == "__init__.py" else parts[:-1]


def _imports(module: str, py: Path, tree: ast.Module, top_level_only: bool = False):
    """(target module, imported names, node) for every opticalstamp import."""
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            if node.level:
                pkg = _package(module, py)
                base = pkg[: len(pkg) - node.level + 1]
                target = ".".join([*base, node.module] if node.module else base)
            elif (node.module or "").startswith("opticalstamp"):
                target = node.module.removeprefix("opticalstamp").lstrip(".")
            else:
                continue
            names = [a.name for a in node.names]
            if not node.module:  # from . import a, b: modules
                for n in names:
                    yield (f"{target}.{n}" if target else n), [], node
            else:
                yield target, names, node
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("opticalstamp."):
                    yield a.name.removeprefix("opticalstamp."), [], node


def _stage(module: str) -> str:
    return module.split(".")[0]


MODULES = list(_modules())


def test_every_module_belongs_to_a_stage():
    stray = [m for m, _, _ in MODULES if m != "__init__" and _stage(m) not in ORDER]
    assert stray == []


def test_stages_import_only_earlier_stages():
    bad = []
    for module, py, tree in MODULES:
        if module == "__init__":
            continue
        me = ORDER.index(_stage(module))
        for target, _, node in _imports(module, py, tree):
            if target and _stage(target) in ORDER and ORDER.index(_stage(target)) > me:
                bad.append(f"{module}:{node.lineno} imports {target}")
    assert bad == []


def test_no_import_cycles():
    graph = {m: set() for m, _, _ in MODULES}
    for module, py, tree in MODULES:
        for target, _, _ in _imports(module, py, tree, top_level_only=True):
            if target in graph and target != module:
                graph[module].add(target)
    state: dict[str, int] = {}

    def visit(m, trail):
        if state.get(m) == 1:
            pytest.fail("import cycle: " + " -> ".join([*trail, m]))
        if state.get(m) == 2:
            return
        state[m] = 1
        for t in sorted(graph[m]):
            visit(t, [*trail, m])
        state[m] = 2

    for m in graph:
        visit(m, [])


def _imports_of(tree: ast.Module) -> set[str]:
    """Every module an absolute import statement names, nested ones included (``from
    scipy import signal`` as scipy and scipy.signal)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            out.add(node.module)
            out |= {f"{node.module}.{a.name}" for a in node.names}
    return out


def _third_party(tree: ast.Module) -> set[str]:
    return {name.split(".")[0] for name in _imports_of(tree)}


@pytest.mark.parametrize(
    ("library", "allowed"),
    [("matplotlib", ("report.plotting",)), ("typer", ("cli",)), ("click", ("cli",))],
)
def test_libraries_stay_at_their_edge(library, allowed):
    bad = [
        m
        for m, _, tree in MODULES
        if library in _third_party(tree) and not any(m.startswith(a) for a in allowed)
    ]
    assert bad == []


#: SciPy subpackages that take about a second to import (SciPy 1.17: scipy.signal, which
#: imports scipy.stats, ~1.4 s), paid by every process that loads them: a scan, each
#: process a report, a search, a tolerance study or a fit spawns -> the modules allowed to
#: import them (inside the function that needs them) and why
SLOW_SCIPY = {"scipy.signal": {"analysis.wavespectral": "czt, a light of several "
              "wavelengths resampled onto one grid"}, "scipy.stats": {}}  # fmt: skip


def test_slow_scipy_subpackages_only_where_allowed():
    """No module imports scipy.signal or scipy.stats but those allowed, and each exception
    is still needed (a small `opticalstamp scan` took 4.0 s with them, 2.3 s without)."""
    found = {
        (m, lib)
        for m, _, tree in MODULES
        for name in _imports_of(tree)
        for lib in SLOW_SCIPY
        if name == lib or name.startswith(lib + ".")
    }
    allowed = {(m, lib) for lib, modules in SLOW_SCIPY.items() for m in modules}
    assert found - allowed == set()
    assert allowed <= found, allowed - found


#: calls that change process-wide state
FORBIDDEN_CALLS = {
    "matplotlib.use",
    "np.random.seed",
    "numpy.random.seed",
    "warnings.simplefilter",
    "warnings.filterwarnings",
    "logging.basicConfig",
    "signal.signal",
    "numba.set_num_threads",
    "nb.set_num_threads",
    "set_num_threads",
    "os.putenv",
    "os.unsetenv",
    "os.getenv",
    "os.environ.get",
    "os.environ.update",
    "os.environ.setdefault",
    "os.environ.pop",
    "os.environ.clear",
}

#: the exceptions, each with its reason: (module, what) -> why it is allowed
ALLOWED_STATE = MappingProxyType(
    {
        ("io.files", "sets Image.MAX_IMAGE_PIXELS"): "Pillow has no per-call pixel limit: "
        "io.files lifts it inside one context manager and restores it on leaving (its "
        "header checks replace the limit with a memory estimate)",
        ("raytrace.cuda_ray", "setattr np"): "numba-cuda <= 0.30 names np.row_stack (gone "
        "in numpy 2.5) when its array module is imported: lent for that import only and "
        "taken back (_row_stack_for_numba_cuda)",
        ("raytrace.cuda_ray", "delattr np"): "the same loan, taken back",
        ("studies.runner", "numba.set_num_threads"): "the initializer of the pool's worker "
        "processes (spawned for the study, one numba thread each): their whole state",
        ("report.background", "numba.set_num_threads"): "Background.cores, which sets this "
        "process's threads for a section and restores them (issue 22: to go with the "
        "report's own pool)",
        ("imaging.ocr", "reads os.environ"): "the tesseract subprocess's environment: a copy "
        "with its thread limit, nothing read for the library",
    }
)


def _module_names(tree: ast.Module) -> set[str]:
    """Names bound to modules by the module's ``import`` statements."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return out | {"np", "numba", "nb", "optuna", "os", "sys"}


def _state_changes(tree: ast.Module) -> list[tuple[int, str]]:
    """(line, what) for every change of process-wide state the guard knows."""
    mods = _module_names(tree)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = ast.unparse(node.func)
            if name in FORBIDDEN_CALLS:
                out.append((node.lineno, name))
            if name in ("setattr", "delattr") and node.args:
                first = node.args[0]
                if isinstance(first, ast.Name) and (first.id in mods or first.id[0].isupper()):
                    out.append((node.lineno, f"{name} {first.id}"))
        if isinstance(node, ast.Attribute) and ast.unparse(node) == "os.environ":
            out.append((node.lineno, "reads os.environ"))
        if isinstance(node, ast.Assign | ast.AugAssign | ast.Delete):
            targets = node.targets if isinstance(node, ast.Assign | ast.Delete) else [node.target]
            for t in targets:  # an attribute of another module, e.g. Image.MAX_IMAGE_PIXELS
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name):
                    if t.value.id[0].isupper() or t.value.id in mods:
                        out.append((node.lineno, f"sets {ast.unparse(t)}"))
                if isinstance(t, ast.Subscript) and ast.unparse(t.value) == "os.environ":
                    out.append((node.lineno, "writes os.environ"))
    return out


def test_no_process_wide_state_is_changed():
    """No environment read or written, no module attribute patched (assigned, setattr or
    delattr), no thread count or global seed set, but the exceptions of ALLOWED_STATE."""
    bad = []
    for module, _, tree in MODULES:
        for line, what in _state_changes(tree):
            if (module, what) not in ALLOWED_STATE:
                bad.append(f"{module}:{line} {what}")
    assert bad == []


def test_the_state_guard_sees_what_it_forbids():
    """The guard finds each kind of change in a module written to break it."""
    code = (
        "import os\nimport numpy as np\nimport numba\n"
        "os.environ['OPTICALSTAMP_DEVICE'] = 'cuda'\n"
        "x = os.environ.get('OPTICALSTAMP_DEVICE')\n"
        "setattr(np, 'row_stack', np.vstack)\n"
        "np.row_stack = np.vstack\n"
        "numba.set_num_threads(1)\n"
    )
    found = {what for _, what in _state_changes(ast.parse(code))}
    assert {"writes os.environ", "os.environ.get", "setattr np", "sets np.row_stack"} <= found
    assert "numba.set_num_threads" in found


def test_the_allowed_exceptions_are_still_there():
    """Each exception of ALLOWED_STATE names a change its module still makes (an
    exception no longer needed is removed, not left to excuse a new one)."""
    seen = {(m, what) for m, _, tree in MODULES for _, what in _state_changes(tree)}
    assert set(ALLOWED_STATE) <= seen, set(ALLOWED_STATE) - seen


def test_module_level_state_is_immutable():
    """No module-level list, dict or set that code could mutate (constants are tuples)."""
    bad = []
    for module, _, tree in MODULES:
        for node in tree.body:
            if isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(
                node.value, ast.List | ast.Dict | ast.Set | ast.ListComp | ast.DictComp
            ):
                if module.startswith("cli") or ast.unparse(node).startswith("__all__"):
                    continue
                bad.append(f"{module}:{node.lineno} {ast.unparse(node)[:60]}")
    assert bad == []


def test_no_private_names_across_modules():
    bad = []
    for module, py, tree in MODULES:
        for target, names, node in _imports(module, py, tree):
            for n in names:
                if n.startswith("_") and n != "__version__":
                    bad.append(f"{module}:{node.lineno} imports {n} from {target}")
    assert bad == []


#: the project's length rule (DESIGN.md §5): a module longer than this is split by concept
MAX_LINES = 600
#: the modules still longer, each with its reason (issue 22 splits them); the guard fails
#: for any other module that grows past MAX_LINES
LONG_MODULES = MappingProxyType({})


def test_modules_stay_under_the_length_rule():
    long = {
        m: n
        for m, py, _ in MODULES
        if (n := len(py.read_text().splitlines())) > MAX_LINES and m not in LONG_MODULES
    }
    assert long == {}


#: the modules that know where a batch's rays are (issue 22's tally layer)
TALLY_MODULES = ("analysis.tallies", "analysis.cuda_tallies")


def _device_branches(module: str, py: Path, tree: ast.Module) -> list[str]:
    """Where ``module`` asks where rays were traced (an attribute ``.device``) or reaches
    for the GPU's tallies (an import of analysis.cuda_tallies)."""
    out = [
        f"{module}:{node.lineno} {ast.unparse(node)}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and node.attr == "device"
    ]
    out += [
        f"{module}:{node.lineno} imports {target}"
        for target, _, node in _imports(module, py, tree)
        if target == "analysis.cuda_tallies"
    ]
    return out


def test_no_analysis_branches_on_the_device():
    """The analyses feed tally objects (analysis/tallies.py), which tally each batch on
    the CPU or on the GPU where it is: no other analysis module reads a batch's
    ``.device`` or imports the GPU's tallies."""
    bad = [
        line
        for module, py, tree in MODULES
        if module.startswith("analysis.") and module not in TALLY_MODULES
        for line in _device_branches(module, py, tree)
    ]
    assert bad == []
    code = "from . import cuda_tallies as gpu\nif pb.rays.device is not None:\n    pass\n"
    py = SRC / "analysis" / "x.py"
    assert len(_device_branches("analysis.x", py, ast.parse(code))) == 2  # the guard sees


#: one ray's arithmetic, defined once in raytrace/rayops.py and compiled for each device
PER_RAY = ("mix", "uniform_pair", "centred", "hole", "fresnel_sp", "advance", "trace_one",
           "reach", "solve_rho", "plain_draw", "importance_draw", "plain_sample")  # fmt: skip
#: other definitions of those names, each with its reason
PER_RAY_ELSEWHERE = MappingProxyType(
    {
        ("raytrace.sampling", "solve_rho"): "the Newton solve vectorised over a table of "
        "holes (the importance table's probabilities, not a ray); checked against the per-ray "
        "solve to 1e-14 in tests/test_rayops.py",
        ("raytrace.sampling", "reach"): "its lateral reach, vectorised over the same table",
        ("analysis.own_etendue", "reach"): "the closed-form own path's hole edges per plane "
        "(rho, plane) for its quadrature: another quantity of the same name",
        ("analysis.wavefilter", "fresnel_sp"): "the wave engine's transmittances over an "
        "angular spectrum (0 past the critical angle); checked against the tracer's to 1e-15 "
        "in tests/test_wave_fresnel.py",
        ("studies.fitwave", "reach"): "the half width a spread's tails reach: another "
        "quantity of the same name",
    }
)


def test_one_definition_of_each_per_ray_function():
    """The per-ray functions (names and their underscored forms) are defined in
    raytrace/rayops.py only, but the exceptions listed with their reason."""
    names = {*PER_RAY, *(f"_{n}" for n in PER_RAY)}
    bad = [
        f"{module}:{node.lineno} {node.name}"
        for module, _, tree in MODULES
        if module != "raytrace.rayops"
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef) and node.name in names
        if (module, node.name.lstrip("_")) not in PER_RAY_ELSEWHERE
    ]
    assert bad == []
    defined = {n.name for m, _, t in MODULES if m == "raytrace.rayops" for n in ast.walk(t)
               if isinstance(n, ast.FunctionDef)}  # fmt: skip
    assert set(PER_RAY) - {"plain_sample"} <= defined
