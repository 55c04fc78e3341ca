"""The package's architecture in numbers: import cycles, imports against the layers, private names taken
across files, function-local imports, large files and functions, the fields of the ``*Options`` classes, and the
module constants of the deciding layers (upper-case names bound to a number or a tuple of numbers in ``pipeline``,
``imaging`` and ``irregular``: the tuned values beside the options).

    python benchmarks/architecture.py [--root jaxlimb] [--json out.json] [--list]

Every number is read from the source (``ast``), nothing is imported.  The layers are those of
``docs/design.md`` (and of the import-linter contract in ``pyproject.toml``).  An import inside
``if TYPE_CHECKING:`` is not counted (it never runs).
"""

from __future__ import annotations

import argparse
import ast
import json
import pathlib
from collections import defaultdict

#: The layers, bottom first; a module's layer is that of its first package under ``jaxlimb``
#: (the top-level modules ``errors``, ``numerics``, ``_validate``, ``_io`` ... are the core).
LAYERS = (("core",), ("models", "geometry", "conics"), ("fitting",), ("imaging", "render"), ("pipeline",),
          ("analysis", "irregular", "track"), ("cli",))
#: Function-local imports allowed: optional or heavy third-party dependencies imported where they are used.
HEAVY = {"matplotlib", "dask", "distributed", "emcee", "corner", "spiceypy", "trimesh", "embreex", "skyfield",
         "astropy", "pdr", "vicar", "cv2", "scipy", "tqdm", "filelock", "PIL", "imageio", "tifffile", "hypothesis",
         "jax", "numpy", "equinox", "optimistix", "lineax", "rms_vicar", "psutil", "sunpy", "glymur"}


def _modules(root: pathlib.Path) -> dict[str, pathlib.Path]:
    pkg = root.name
    out = {}
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    assert pkg in out
    return out


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                skip.update(id(n) for n in ast.walk(sub))
    return skip


def _resolve(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(mods: dict[str, pathlib.Path]):
    """Per module: ``(target, names, local, lineno)`` for every import statement (targets resolved to modules)."""
    out: dict[str, list] = {}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text())
        skip = _type_checking_nodes(tree)
        funcs = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
        local_ids = {id(x) for f in funcs for x in ast.walk(f)}
        rows = []
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            local = id(node) in local_ids
            if isinstance(node, ast.Import):
                for a in node.names:
                    rows.append((a.name, (), local, node.lineno))
            elif isinstance(node, ast.ImportFrom):
                tgt = _resolve(mod, path.name == "__init__.py", node)
                names = tuple(a.name for a in node.names)
                subs = [f"{tgt}.{n}" for n in names if f"{tgt}.{n}" in mods]
                rows.append((tgt, tuple(n for n in names if f"{tgt}.{n}" not in mods), local, node.lineno))
                rows.extend((s, (), local, node.lineno) for s in subs)
        out[mod] = rows
    return out


def _layer(mod: str) -> int | None:
    parts = mod.split(".")
    top = parts[1] if len(parts) > 1 else None
    if top is None:
        return None
    for i, names in enumerate(LAYERS):
        if top in names:
            return i
    return 0 if (top.startswith("_") or top in ("errors", "numerics")) else None


def _sccs(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def _options_fields(mods: dict[str, pathlib.Path]) -> dict[str, int]:
    out = {}
    for mod, path in mods.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and node.name.endswith("Options"):
                n = sum(1 for s in node.body if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)
                        and "ClassVar" not in ast.unparse(s.annotation))
                out[f"{mod}.{node.name}"] = n
    return out


#: The packages whose module constants are counted (where ``locate`` and the line of sight decide).
DECIDING = ("pipeline", "imaging", "irregular")


def _numeric(node: ast.AST) -> bool:
    """A number, a signed or computed number, or a tuple of them."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, ast.UnaryOp):
        return _numeric(node.operand)
    if isinstance(node, ast.BinOp):
        return _numeric(node.left) and _numeric(node.right)
    return isinstance(node, ast.Tuple) and bool(node.elts) and all(_numeric(e) for e in node.elts)


def _module_constants(mods: dict[str, pathlib.Path]) -> list[str]:
    out = []
    for mod, path in mods.items():
        parts = mod.split(".")
        if len(parts) < 2 or parts[1] not in DECIDING:
            continue
        for node in ast.parse(path.read_text()).body:
            targets = node.targets if isinstance(node, ast.Assign) else (
                [node.target] if isinstance(node, ast.AnnAssign) and node.value is not None else [])
            out += [f"{mod}.{t.id}" for t in targets
                    if isinstance(t, ast.Name) and t.id.isupper() and _numeric(node.value)]
    return sorted(out)


def census(root: str = "jaxlimb") -> dict:
    mods = _modules(pathlib.Path(root))
    pkg = pathlib.Path(root).name
    imps = _imports(mods)
    graph: dict[str, set[str]] = defaultdict(set)
    up, private, local_internal, local_external, local_heavy = [], [], [], [], []
    for mod, rows in imps.items():
        graph[mod]
        for tgt, names, local, line in rows:
            internal = tgt == pkg or tgt.startswith(pkg + ".")
            if internal:
                t = tgt
                while t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t != mod:
                    graph[mod].add(t)
                lm, lt = _layer(mod), _layer(t)
                if lm is not None and lt is not None and lt > lm:
                    up.append(f"{mods[mod]}:{line} {mod} -> {t}")
                bad = [n for n in names if n.startswith("_") and not n.startswith("__")]
                if bad and t != mod:
                    private.append(f"{mods[mod]}:{line} {','.join(bad)} from {t}")
                if local:
                    local_internal.append(f"{mods[mod]}:{line}")
            elif local:
                top = tgt.split(".")[0]
                (local_heavy if top in HEAVY else local_external).append(f"{mods[mod]}:{line} {top}")
    local_internal, local_external, local_heavy = (sorted(set(x)) for x in (local_internal, local_external, local_heavy))
    cycles = _sccs(graph)
    lines = {str(p): len(p.read_text().splitlines()) for p in mods.values()}
    funcs = []
    for p in mods.values():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                funcs.append((node.end_lineno - node.lineno + 1, f"{p}:{node.lineno} {node.name}"))
    opts = _options_fields(mods)
    return {
        "import_cycles": cycles,
        "upward_imports": up,
        "private_cross_file_imports": private,
        "function_local_imports_internal": local_internal,
        "function_local_imports_other": local_external,
        "function_local_imports_heavy": local_heavy,
        "files_over_500": sorted((n, f) for f, n in lines.items() if n > 500),
        "functions_over_60": sorted(f for f in funcs if f[0] > 60),
        "options_fields": opts,
        "module_constants": _module_constants(mods),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default="jaxlimb")
    ap.add_argument("--json")
    ap.add_argument("--list", action="store_true", help="list every item, not only the counts")
    ap.add_argument("--under", default=None, help="count files/functions/options under this path prefix only")
    a = ap.parse_args()
    c = census(a.root)
    if a.under:
        keep = lambda s: a.under in s  # noqa: E731
        c["files_over_500"] = [x for x in c["files_over_500"] if keep(x[1])]
        c["functions_over_60"] = [x for x in c["functions_over_60"] if keep(x[1])]
        for k in ("upward_imports", "private_cross_file_imports", "function_local_imports_internal",
                  "function_local_imports_other", "function_local_imports_heavy"):
            c[k] = [x for x in c[k] if keep(x)]
        c["module_constants"] = [x for x in c["module_constants"] if keep(x.replace(".", "/"))]
        c["options_fields"] = {k: v for k, v in c["options_fields"].items() if keep(k.replace(".", "/"))}
    for k, v in c.items():
        if k == "options_fields":
            print(f"{k}: {sum(v.values())} in {len(v)} classes")
            if a.list:
                for name, n in sorted(v.items(), key=lambda x: -x[1]):
                    print(f"    {n:4d}  {name}")
            continue
        print(f"{k}: {len(v)}")
        if a.list:
            for x in v:
                print("    ", x)
    if a.json:
        pathlib.Path(a.json).write_text(json.dumps(c, indent=1, default=str))


if __name__ == "__main__":
    main()
