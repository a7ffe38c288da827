"""Layering and naming rules of the package, checked on its source (DEVELOPERS' style rules).

- collide/ finds contacts and knows nothing of the solver: it imports nothing from solvers/.
- schedule/ (colours, slabs) is built from the pairs alone: it imports neither collide/ nor
  solvers/.
- Kernel arguments are grouped under comments naming where they come from (mujoco_warp's
  convention): every kernel of more than 8 parameters has groups, each group comment uses the
  fixed vocabulary, and arguments under ``# Model`` / ``# State ...`` are named exactly like
  the Model / State fields they are passed (State fields may carry an ``_in`` / ``_out`` suffix
  when a kernel takes both buffers).
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


def modules(folder: Path):
    return sorted(folder.rglob("*.py"))


def imported_packages(path: Path) -> set[str]:
    """Subpackages of warp_sim that ``path`` imports (relative or absolute)."""
    tree = ast.parse(path.read_text())
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
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
    """The check above can fail: a relative import of the solver from collide/ is caught."""
    fake = PACKAGE / "collide" / "_probe_for_test.py"
    try:
        fake.write_text("from ..solvers.solver import SoftStepSolver\n")
        assert imported_packages(fake) == {"solvers"}
    finally:
        fake.unlink()


def kernels():
    for path in modules(PACKAGE):
        source = path.read_text()
        lines = source.split("\n")
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.FunctionDef) and any("wp.kernel" in ast.unparse(d) for d in node.decorator_list):
                yield path, node, lines


def field_names():
    import warp as wp

    from warp_sim import ModelBuilder
    from warp_sim.state import State

    wp.config.quiet = True
    b = ModelBuilder()
    b.add_sphere(0.5, 1.0, position=(0.0, 1.0, 0.0))
    model = b.finalize("cpu")
    model_fields = set(vars(model)) | {k for k in dir(type(model)) if not k.startswith("_")}
    state_fields = set(re.findall(r"self\.(\w+)\s*=", inspect.getsource(State)))
    return model_fields, state_fields


def test_kernel_arguments_are_grouped_and_named_like_their_fields():
    model_fields, state_fields = field_names()
    assert {"body_inv_mass", "body_shape"} <= model_fields and {"body_pos", "body_vel"} <= state_fields
    problems = []
    for path, node, lines in kernels():
        where = f"{path.relative_to(ROOT)}:{node.lineno} {node.name}"
        arg_line = {a.lineno: a.arg for a in node.args.args}
        comments = [lines[k - 1].strip() for k in range(node.lineno, node.body[0].lineno)
                    if lines[k - 1].strip().startswith("#")]
        groups = [c for c in comments if GROUP.match(c)]
        if len(node.args.args) > 8 and not groups:
            problems.append(f"{where}: {len(node.args.args)} parameters and no group comments")
        group = None
        for k in range(node.lineno, node.body[0].lineno):
            text = lines[k - 1].strip()
            match = GROUP.match(text)
            if match:
                group = match.group(1)
            if k not in arg_line:
                continue
            name = arg_line[k]
            if group == "Model" and name not in model_fields:
                problems.append(f"{where}: '{name}' under # Model is no Model field")
            if group is not None and group.startswith("State") and re.sub(r"_(in|out)$", "", name) not in state_fields:
                problems.append(f"{where}: '{name}' under # {group} is no State field")
    assert not problems, "\n".join(problems)


def test_no_module_is_overlong():
    long = {str(p.relative_to(ROOT)): n for p in modules(PACKAGE) if (n := len(p.read_text().split("\n"))) > MAX_LINES}
    assert not long
