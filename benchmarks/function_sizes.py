"""Sizes of the functions of a package: lines and branch points (if/for/while/try/with/bool ops/
comprehension conditions/ternaries), largest first.

    python benchmarks/function_sizes.py jaxlimb/pipeline [--top 15] [--json out.json]
"""

from __future__ import annotations

import argparse
import ast
import json
import pathlib

_BRANCHES = (ast.If, ast.For, ast.While, ast.Try, ast.IfExp, ast.ExceptHandler, ast.With, ast.comprehension,
             ast.AsyncFor, ast.match_case)


def _branches(fn: ast.AST) -> int:
    n = 0
    for node in ast.walk(fn):
        if isinstance(node, _BRANCHES):
            n += 1
        elif isinstance(node, ast.BoolOp):
            n += len(node.values) - 1
    return n


def function_sizes(root: str) -> list[dict[str, object]]:
    """``[{"function", "file", "lines", "branches"}]`` for every (nested) function under ``root``."""
    out = []
    for path in sorted(pathlib.Path(root).rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                out.append({"function": node.name, "file": str(path), "lines": node.end_lineno - node.lineno + 1,
                            "branches": _branches(node)})
    return sorted(out, key=lambda d: -int(d["lines"]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root")
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--json")
    a = ap.parse_args()
    rows = function_sizes(a.root)
    for r in rows[: a.top]:
        print(f"{r['lines']:5d} lines {r['branches']:4d} branches  {r['function']}  ({r['file']})")
    print(f"{len(rows)} functions; {sum(1 for r in rows if int(r['lines']) > 80)} over 80 lines")
    if a.json:
        pathlib.Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
