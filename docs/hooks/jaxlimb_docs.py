"""MkDocs hooks of the jaxlimb site.

* ``<!-- cli-reference -->`` in a page becomes the reference of every ``jaxlimb`` sub-command, generated from
  the argparse parser the command itself uses (:func:`jaxlimb.cli.build_parser`), so the page cannot drift
  from ``--help``.
* ``<!-- api: jaxlimb.PACKAGE -->`` becomes the mkdocstrings directive for the package's public names: its
  ``__all__``, else the names it re-exports (``from .mod import X as X``) and defines.
* ``<!-- results: NAME ARG... -->`` becomes a table read from ``benchmarks/results/`` (``results_tables.py``;
  the track page's in ``track_tables.py``, the real frames' in ``real_frames_tables.py``, the posteriors' in
  ``uncertainty_tables.py``).
* ``<!-- schema: NAME -->`` becomes the key table and the text of ``jaxlimb/schemas/NAME.schema.json``
  (``schema_tables.py``).
* The notebooks of ``notebooks/`` are pages under ``notebooks/``.  They are committed without outputs; set
  ``JAXLIMB_DOCS_EXECUTED=DIR`` to render executed copies from ``DIR/notebooks/`` instead (``make docs``
  executes them with nbconvert into ``build/docs-executed/notebooks/`` first).
* The figures of ``benchmarks/results/*.png`` are served under ``results/``.
* ``design.md``, ``guarantees.md`` and ``track.md`` are optional while they are written: a missing one leaves
  the navigation, and links to it become plain text.  Every other missing page or link fails the build.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import os
import re
import sys
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = ROOT / "notebooks"
OPTIONAL_PAGES = ("design.md", "guarantees.md", "track.md")
log = logging.getLogger("mkdocs.hooks.jaxlimb")



def _load_sibling(module: str, file: str):  # noqa: ANN202
    """A module of this folder (MkDocs loads a hook by path: its folder is not importable)."""
    spec = importlib.util.spec_from_file_location(module, Path(__file__).with_name(file))
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


results_tables = _load_sibling("jaxlimb_results_tables", "results_tables.py")
track_tables = _load_sibling("jaxlimb_track_tables", "track_tables.py")  # registers the track page's tables
real_frames_tables = _load_sibling("jaxlimb_real_frames_tables", "real_frames_tables.py")  # the real-frames page's
uncertainty_tables = _load_sibling("jaxlimb_uncertainty_tables", "uncertainty_tables.py")  # the posteriors'
schema_tables = _load_sibling("jaxlimb_schema_tables", "schema_tables.py")


# ----------------------------------------------------------------------------------------- pages others write
def _missing_optional(config) -> set[str]:
    docs = Path(config["docs_dir"])
    return {p for p in OPTIONAL_PAGES if not (docs / p).is_file()}


def _prune(nav, missing: set[str]):
    out = []
    for item in nav:
        if isinstance(item, dict):
            (title, value), = item.items()
            if isinstance(value, list):
                out.append({title: _prune(value, missing)})
            elif value not in missing:
                out.append(item)
        elif item not in missing:
            out.append(item)
    return out


def on_config(config):
    missing = _missing_optional(config)
    if missing:
        log.info("pages not written yet, left out of the navigation: %s", ", ".join(sorted(missing)))
        config["nav"] = _prune(config["nav"], missing)
    return config


# ----------------------------------------------------------------------------------------- notebooks
@event_priority(100)  # before mkdocs-jupyter turns .ipynb files into pages
def on_files(files, config):
    executed = os.environ.get("JAXLIMB_DOCS_EXECUTED")
    root = Path(executed).resolve() if executed else ROOT  # holds notebooks/NAME.ipynb
    for nb in sorted(NOTEBOOKS.glob("*.ipynb")):
        if not (root / "notebooks" / nb.name).is_file():
            raise PluginError(f"JAXLIMB_DOCS_EXECUTED={executed}: notebooks/{nb.name} is missing (run `make docs`)")
        files.append(File(f"notebooks/{nb.name}", str(root), config["site_dir"], config["use_directory_urls"]))
    bench = ROOT / "benchmarks"
    for png in sorted((bench / "results").glob("*.png")):  # figures the validation pages show, not copied
        files.append(File(f"results/{png.name}", str(bench), config["site_dir"], config["use_directory_urls"]))
    return files


# ----------------------------------------------------------------------------------------- page markdown
_RESULTS = re.compile(r"<!--\s*results:\s*(\w+)((?:\s+[^\s>]+)*)\s*-->")
_OPTIONAL_LINK = re.compile(r"\[([^\]]+)\]\((?:\.\./)*(" + "|".join(map(re.escape, OPTIONAL_PAGES)) + r")(#[^)]*)?\)")


_API = re.compile(r"<!--\s*api:\s*([\w.]+)\s*-->")
_SCHEMA = re.compile(r"<!--\s*schema:\s*(\w+)\s*-->")


def on_page_markdown(markdown, page, config, files):
    if "<!-- cli-reference -->" in markdown:
        markdown = markdown.replace("<!-- cli-reference -->", cli_reference())
    markdown = _API.sub(lambda m: api_directive(m.group(1)), markdown)

    def _table(m: re.Match) -> str:
        name, args = m.group(1), m.group(2).split()
        try:
            return results_tables.render(name, args)
        except KeyError:
            raise PluginError(f"{page.file.src_uri}: unknown results table {name!r}; known: {results_tables.names()}")
        except FileNotFoundError as e:
            raise PluginError(f"{page.file.src_uri}: {e}") from None

    markdown = _RESULTS.sub(_table, markdown)

    def _schema(m: re.Match) -> str:
        if m.group(1) not in schema_tables.names():
            raise PluginError(f"{page.file.src_uri}: unknown schema {m.group(1)!r}; known: {schema_tables.names()}")
        return schema_tables.render(m.group(1))

    markdown = _SCHEMA.sub(_schema, markdown)
    missing = _missing_optional(config)
    if missing:
        markdown = _OPTIONAL_LINK.sub(lambda m: m.group(1) if m.group(2) in missing else m.group(0), markdown)
    return markdown


# ----------------------------------------------------------------------------------------- docstring roles
_ROLE = re.compile(r":(?:func|class|data|mod|meth|attr|exc|obj|const):<code>~?([^<]*)</code>")
_MATH = re.compile(r":math:<code>([^<]*)</code>")
_ROLE_LITERAL = re.compile(r":(?:func|class|data|mod|meth|attr|exc|obj|const):`~?([^`]*)`")  # inside code spans


def on_page_content(html, page, config, files):
    """The docstrings are numpydoc with reStructuredText roles: ``:func:`x``` reads as ``x``, ``:math:`...``` is
    typeset by MathJax."""
    if not page.file.src_uri.startswith("api/"):
        return html
    html = _ROLE.sub(lambda m: f"<code>{m.group(1)}</code>", html)
    html = _ROLE_LITERAL.sub(lambda m: m.group(1), html)
    return _MATH.sub(lambda m: f'<span class="arithmatex">\\({m.group(1)}\\)</span>', html)


# ----------------------------------------------------------------------------------------- CLI reference
def _escape(text: str) -> str:
    text = " ".join(str(text).split())
    return text.replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;").replace("*", "\\*")


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser, str]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            return [(name, p, helps.get(name) or "") for name, p in action.choices.items()]
    return []


def _option_rows(parser: argparse.ArgumentParser) -> list[list[str]]:
    fmt = parser._get_formatter()
    rows = []
    for a in parser._actions:
        if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if a.option_strings:
            metavar = "" if a.nargs == 0 else " " + fmt._format_args(a, a.dest.upper())
            names = ", ".join(f"`{o}{metavar}`" for o in a.option_strings)
        else:
            names = f"`{fmt._format_args(a, a.dest)}`"
        help_ = fmt._expand_help(a) if a.help and a.help != argparse.SUPPRESS else ""
        if a.choices is not None and not isinstance(a, argparse._SubParsersAction):
            help_ += f" (one of: {', '.join(map(str, a.choices))})" if "{" not in names else ""
        rows.append([names, _escape(help_) or "–"])
    return rows


def _command_md(path: str, parser: argparse.ArgumentParser, summary: str, level: int) -> list[str]:
    parser.formatter_class = lambda prog: argparse.HelpFormatter(prog, width=100)
    out = [f"{'#' * level} `{path}`", ""]
    if parser.description:
        out += [_escape(parser.description), ""]
    elif summary:
        out += [_escape(summary[0].upper() + summary[1:]) + ".", ""]
    out += ["```text", parser.format_usage().strip(), "```", ""]
    rows = _option_rows(parser)
    if rows:
        out += ["| argument | meaning |", "|---|---|"] + [f"| {a} | {b} |" for a, b in rows] + [""]
    if parser.epilog:
        out += [_escape(parser.epilog), ""]
    subs = _subcommands(parser)
    if subs:
        out += ["| sub-command | what it does |", "|---|---|"]
        out += [f"| [`{path} {n}`](#{_anchor(path + ' ' + n)}) | {_escape(h)} |" for n, _, h in subs] + [""]
        for name, sub, help_ in subs:
            out += _command_md(f"{path} {name}", sub, help_, level + 1)
    return out


def _anchor(title: str) -> str:
    return re.sub(r"[^a-z0-9_\- ]", "", title.lower()).strip().replace(" ", "-")


def cli_reference() -> str:
    sys.path.insert(0, str(ROOT))
    try:
        from jaxlimb.cli import build_parser
    finally:
        sys.path.pop(0)
    return "\n".join(_command_md("jaxlimb", build_parser(), "", 2))


# ----------------------------------------------------------------------------------------- API pages
def public_names(package: str) -> list[str]:
    """The public names of ``package`` (read from its ``__init__.py``, not imported): ``__all__`` if it has
    one, else its explicit re-exports ``from .mod import X as X`` and its own public definitions, in order."""
    import ast

    init = ROOT.joinpath(*package.split(".")) / "__init__.py"
    tree = ast.parse(init.read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return list(ast.literal_eval(node.value))
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            names += [a.asname for a in node.names if a.asname and a.asname == a.name]
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.append(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.append(node.target.id)
    return [n for n in dict.fromkeys(names) if not n.startswith("_")]


def api_directive(package: str) -> str:
    """The package's public names; a package that re-exports nothing gets one section per public module.

    A name that is also a submodule (``jaxlimb.fitting.fit``, the function, in ``fit.py``) would render as the
    module: it gets its own directive at its defining path."""
    names = public_names(package)
    pkg = ROOT.joinpath(*package.split("."))
    if names:
        shadowed = [n for n in names if (pkg / f"{n}.py").is_file() or (pkg / n / "__init__.py").is_file()]
        plain = [n for n in names if n not in shadowed]
        out = [f"::: {package}\n    options:\n      members: [{', '.join(plain)}]\n"]
        out += [f"::: {package}.{n}.{n}\n    options:\n      heading_level: 3\n" for n in shadowed]
        return "\n".join(out)
    modules = sorted(p.stem for p in pkg.glob("*.py") if not p.stem.startswith("_"))
    if not modules:
        raise PluginError(f"{package}: no public names or modules found for its API page")
    out = [f"::: {package}\n    options:\n      members: false\n"]
    out += [f"::: {package}.{m}\n    options:\n      heading_level: 2\n" for m in modules]
    return "\n".join(out)
