"""Layering and naming rules of the package, checked on its source (DEVELOPERS' style rules).

- collide/ finds contacts and knows nothing of the solver: it imports nothing from solvers/.
- schedule/ (colours, slabs) is built from the pairs alone: it imports neither collide/ nor
  solvers/.
- Kernel arguments are grouped under comments naming where they come from (mujoco_warp's
  convention): every kernel of more than 8 parameters has groups, each group comment uses the
  fixed vocabulary, and arguments under ``# Model`` / ``# State ...`` are named exactly like
  the Model / State fields they are passed (State fields may carry an ``_in`` / ``_out`` suffix
  when a kernel takes both buffers).  Arrays mostly travel in Warp structs (kernel_args.py): an
  argument whose type is one of the package's structs is named freely, and the struct's fields
  follow the same rule, with ``# Contacts ...`` / ``# Solver ...`` fields named like Contacts /
  SoftStepSolver fields too.
- No kernel or func takes more than 25 parameters (a struct counts as one).
- No module of the package is longer than 650 lines.
"""

import ast
import inspect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "warp_sim"
GROUP = re.compile(r"# (Model|Settings|State in/out|State in|State out|Contacts in/out|Contacts in|Contacts out|"
                   r"Solver in/out|Solver in|Solver out|Sleep in/out|Sleep in|Broad phase in|In|Out|Scratch)\b")
MAX_LINES = 650
MAX_PARAMETERS = 25


def modules(folder: Path):
    return sorted(folder.rglob("*.py"))


def imported_packages(path: Path, root: Path = ROOT) -> set[str]:
    """Subpackages of warp_sim that ``path`` (a file under ``root``) imports (relative or absolute)."""
    tree = ast.parse(path.read_text())
    package = path.relative_to(root).with_suffix("").parts[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(package[: len(package) - node.level + 1])
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            parts = name.split(".")
            if parts[0] == "warp_sim" and len(parts) > 1:
                found.add(parts[1])
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "warp_sim" and len(parts) > 1:
                    found.add(parts[1])
    return found


@pytest.mark.parametrize("folder, forbidden", [("collide", {"solvers"}), ("schedule", {"solvers", "collide"})])
def test_layers_import_only_downwards(folder, forbidden):
    offenders = {str(p.relative_to(ROOT)): sorted(imported_packages(p) & forbidden)
                 for p in modules(PACKAGE / folder) if imported_packages(p) & forbidden}
    assert not offenders


def test_the_import_check_sees_relative_imports(tmp_path):
    """The check above can fail: a relative import of the solver from collide/ is caught.  The
    probe lies in a copy of the layout under tmp_path: written into the package, it was read by
    the check above when the two ran at once in two test processes."""
    fake = tmp_path / "warp_sim" / "collide" / "probe.py"
    fake.parent.mkdir(parents=True)
    fake.write_text("from ..solvers.solver import SoftStepSolver\n")
    assert imported_packages(fake, tmp_path) == {"solvers"}


def decorated(node, decorator: str) -> bool:
    return any(decorator in ast.unparse(d) for d in node.decorator_list)


def definitions(decorator: str):
    for path in modules(PACKAGE):
        source = path.read_text()
        lines = source.split("\n")
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and decorated(node, decorator):
                yield path, node, lines


def kernels():
    yield from definitions("wp.kernel")


def field_names():
    import warp as wp

    from warp_sim import ModelBuilder
    from warp_sim.contacts import Contacts
    from warp_sim.solvers.solver import SoftStepSolver
    from warp_sim.state import State

    wp.config.quiet = True
    b = ModelBuilder()
    b.add_sphere(0.5, 1.0, position=(0.0, 1.0, 0.0))
    model = b.finalize("cpu")
    model_fields = set(vars(model)) | {k for k in dir(type(model)) if not k.startswith("_")}
    state_fields = set(re.findall(r"self\.(\w+)\s*=", inspect.getsource(State)))
    contacts_fields = set(re.findall(r"self\.(\w+)\s*=", inspect.getsource(Contacts)))
    solver_fields = set(re.findall(r"self\.(\w+)\s*=", inspect.getsource(SoftStepSolver)))
    return {"Model": model_fields, "State": state_fields, "Contacts": contacts_fields,
            "Solver": solver_fields}


def entries(node, lines):
    """(line, name, annotation) of a kernel's parameters or a struct's fields, and the line the
    group comments above them end at."""
    if isinstance(node, ast.ClassDef):
        fields = [s for s in node.body if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)]
        return [(f.lineno, f.target.id, ast.unparse(f.annotation)) for f in fields], node.body[-1].end_lineno + 1
    args = [(a.lineno, a.arg, ast.unparse(a.annotation) if a.annotation else "") for a in node.args.args]
    return args, node.body[0].lineno


def naming_problems(where: str, node, lines, fields: dict, structs: set, contacts: bool = False) -> list[str]:
    """The grouping and naming rule of the module docstring, for a kernel's parameters or (with
    ``contacts``: Contacts and Solver groups checked too) a struct's fields."""
    problems = []
    named, end = entries(node, lines)
    by_line = {line: (name, annotation) for line, name, annotation in named}
    comments = [lines[k - 1].strip() for k in range(node.lineno, end) if lines[k - 1].strip().startswith("#")]
    if len(named) > 8 and not any(GROUP.match(c) for c in comments):
        problems.append(f"{where}: {len(named)} parameters and no group comments")
    group = None
    for k in range(node.lineno, end):
        match = GROUP.match(lines[k - 1].strip())
        if match:
            group = match.group(1)
        if k not in by_line or group is None:
            continue
        name, annotation = by_line[k]
        if annotation in structs:
            continue  # checked field by field (test_struct_fields_are_named_like_their_fields)
        kind = group.split()[0]
        if kind in ("Contacts", "Solver") and not contacts:
            continue
        if kind in fields and re.sub(r"_(in|out)$", "", name) not in fields[kind]:
            problems.append(f"{where}: '{name}' under # {group} is no {kind} field")
    return problems


def struct_names() -> set[str]:
    return {node.name for _, node, _ in definitions("wp.struct")}


def test_kernel_arguments_are_grouped_and_named_like_their_fields():
    fields = field_names()
    assert {"body_inv_mass", "body_shape"} <= fields["Model"] and {"body_pos", "body_vel"} <= fields["State"]
    structs = struct_names()
    problems = []
    for path, node, lines in kernels():
        problems += naming_problems(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}", node, lines,
                                    fields, structs)
    assert not problems, "\n".join(problems)


def test_struct_fields_are_named_like_their_fields():
    """Every struct of arrays that a kernel or func takes (an argument group; structs of values
    such as BodyVelocity are data, not groups) groups its fields, and fields under # Model,
    # State ..., # Contacts ... and # Solver ... are named exactly like the fields they are
    bound from (kernel_args.bind takes them by name)."""
    fields = field_names()
    assert {"terrain_contact_active", "pair_body"} <= fields["Contacts"]
    used = {ann for _, node, _ in [*kernels(), *definitions("wp.func")] for ann in
            (ast.unparse(a.annotation) for a in node.args.args if a.annotation)}
    problems, checked = [], []
    for path, node, lines in definitions("wp.struct"):
        named, end = entries(node, lines)
        if node.name not in used or not any("wp.array" in annotation for _, _, annotation in named):
            continue
        where = f"{path.relative_to(ROOT)}:{node.lineno} {node.name}"
        if len(named) > 1 and not any(GROUP.match(lines[k - 1].strip()) for k in range(node.lineno, end)):
            problems.append(f"{where}: fields without a group comment")
        problems += naming_problems(where, node, lines, fields, set(), contacts=True)
        checked.append(node.name)
    assert {"BodyModel", "BodyState", "TerrainContacts", "PairContacts", "SolverBodies"} <= set(checked)
    assert not problems, "\n".join(problems)


def test_no_kernel_or_func_takes_more_than_25_parameters():
    long = [f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {len(node.args.args)}"
            for path, node, _ in [*kernels(), *definitions("wp.func")] if len(node.args.args) > MAX_PARAMETERS]
    assert not long, "\n".join(long)


def test_the_naming_check_catches_a_misnamed_struct_field():
    """The rule can fail: a struct field under # Model that is no Model field, and one under
    # Contacts in that is no Contacts field, are reported; a struct-typed argument is not."""
    source = """@wp.struct
class Probe:
    # Model
    body_inv_mass: wp.array(dtype=float)
    inv_mass: wp.array(dtype=float)
    # Contacts in
    terrain_contact_active: wp.array(dtype=wp.int32)
    contact_active: wp.array(dtype=wp.int32)


@wp.kernel
def probe(
    # Model
    model: Probe,
    mass: wp.array(dtype=float),
):
    pass
"""
    lines = source.split("\n")
    struct, kernel = [n for n in ast.parse(source).body]
    fields = field_names()
    assert naming_problems("probe", struct, lines, fields, set(), contacts=True) == [
        "probe: 'inv_mass' under # Model is no Model field",
        "probe: 'contact_active' under # Contacts in is no Contacts field"]
    assert naming_problems("probe", kernel, lines, fields, {"Probe"}) == [
        "probe: 'mass' under # Model is no Model field"]


def test_no_module_is_overlong():
    long = {str(p.relative_to(ROOT)): n for p in modules(PACKAGE) if (n := len(p.read_text().split("\n"))) > MAX_LINES}
    assert not long


def test_no_step_uses_a_native_scan_that_allocates_on_cuda():
    """``wp.utils.array_scan`` allocates CUB's temporary storage on every CUDA call; inside a
    conditional graph body that allocation is refused (every scene with body contact failed its
    first captured step on an H200 this way).  Scans go through warp_sim/prefix_sum.py."""
    users = [str(p.relative_to(ROOT)) for p in modules(PACKAGE)
             if p.name != "prefix_sum.py" and re.search(r"\barray_scan\s*\(", p.read_text())]
    assert not users
