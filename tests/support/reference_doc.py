"""docs/reference.md, generated from the code that defines what it lists:

    python tests/support/reference_doc.py          # rewrite docs/reference.md

- every material model's parameters, from its declaration (engine.materials.catalogue.MODELS);
- every phase function's parameters (engine.media.catalogue.PHASE_MODELS);
- the render settings, from engine.scene.description.RenderSettings (fields, defaults, the comments
  above each field);
- every command-line option, from engine.cli.build_parser.

tests/scene/test_reference_doc.py fails when the file differs from what this module generates.
"""

import argparse
import ast
import dataclasses
import inspect
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PATH = os.path.join(REPO, "docs", "reference.md")


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _declaration_tables(declarations) -> list[str]:
    lines = []
    for decl in declarations:
        lines += [f"### `{decl.name}` — {decl.title}", "", decl.doc, "",
                  "| parameter | allowed | default | per point | meaning |", "|---|---|---|---|---|"]
        for p in decl.parameters:
            default = "required" if p.required else ("—" if p.default is None else f"`{p.default!r}`")
            if p.required and p.only_with is not None:
                default = f"required with `{p.only_with[0]}` = {' or '.join(map(repr, p.only_with[1]))}"
            members = getattr(p, "members", None)
            allowed = p.allowed_text() if p.kind != "coats" or members is None else \
                "a list of coats: " + ", ".join(f"`{q.name}`" for q in members.parameters)
            lines.append(f"| `{p.name}` | {_cell(allowed)} | {_cell(default)} | "
                         f"{'yes' if p.name in decl.per_point else 'no'} | {_cell(p.doc)} |")
        lines.append("")
    return lines


def materials_section() -> list[str]:
    from engine.materials.catalogue import MODELS
    lines = ["## Materials", "",
             "One table per scene-file material `type` (`\"materials\": {\"name\": {\"type\": …}}`); the Blender "
             "Polarising BSDF node shows the same parameters as sockets.", ""]
    return lines + _declaration_tables(MODELS.values())


def phase_section() -> list[str]:
    from engine.media.catalogue import PHASE_MODELS
    lines = ["## Phase functions", "",
             "Phase functions of participating media (engine/media; `python -m engine mueller --model NAME "
             "--scattering-angle DEG`); not yet used by the renderer (issue 37).", ""]
    return lines + _declaration_tables(PHASE_MODELS.values())


def _field_comments(cls) -> dict[str, str]:
    """{field: the ``#:`` comment lines above it and its inline comment} of a dataclass's source."""
    source, first = inspect.getsourcelines(cls)
    tree = ast.parse("".join(source))
    comments = {}
    node = tree.body[0]
    for item in node.body:
        if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
            i = item.lineno - 1
            above = []
            j = i - 1
            while j >= 0 and source[j].strip().startswith("#:"):
                above.insert(0, source[j].strip()[2:].strip())
                j -= 1
            inline = source[i].split("#", 1)[1].strip() if "#" in source[i] else ""
            comments[item.target.id] = " ".join(above + ([inline] if inline else []))
    return comments


def settings_section() -> list[str]:
    from engine.scene.description import RenderSettings
    comments = _field_comments(RenderSettings)
    lines = ["## Render settings", "",
             "The scene file's `render` block and the Python API's `RenderSettings` "
             "(engine.scene.description); command-line options override them.", "",
             inspect.cleandoc(RenderSettings.__doc__), "",
             "| setting | default | meaning |", "|---|---|---|"]
    for f in dataclasses.fields(RenderSettings):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        lines.append(f"| `{f.name}` | `{default!r}` | {_cell(comments.get(f.name, ''))} |")
    return lines + [""]


def _option_row(action) -> str | None:
    if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
        return None
    names = ", ".join(f"`{o}`" for o in action.option_strings) or f"`{action.dest.upper()}`"
    if action.choices is not None and not isinstance(action, argparse._SubParsersAction):
        values = " | ".join(map(str, action.choices))
    elif action.nargs == 0:
        values = "(flag)"
    else:
        values = action.metavar or (action.type.__name__ if action.type else "text")
    default = "" if action.default in (None, False, argparse.SUPPRESS) else f"`{action.default!r}`"
    return f"| {names} | {_cell(values)} | {default} | {_cell(action.help or '')} |"


def cli_section() -> list[str]:
    from engine.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    lines = ["## Command line", "", "`python -m engine COMMAND …` (engine.cli.build_parser).", ""]
    summaries = {a.dest: a.help for a in sub._choices_actions}
    for name, command in sub.choices.items():
        lines += [f"### `{name}`", "", _cell(command.description or summaries.get(name, "")), "",
                  "| option | values | default | meaning |", "|---|---|---|---|"]
        lines += [row for row in map(_option_row, command._actions) if row is not None]
        lines.append("")
    return lines


def generate() -> str:
    sys.path.insert(0, REPO)
    head = ["# Reference", "",
            "Generated by `python tests/support/reference_doc.py` from the declarations, the render settings "
            "and the command-line definitions; a test fails when it is stale.  The user guide "
            "([docs/guide](guide/)) explains how to use them.", ""]
    return "\n".join(head + materials_section() + phase_section() + settings_section() + cli_section()).rstrip() + "\n"


def main():
    text = generate()
    os.makedirs(os.path.dirname(PATH), exist_ok=True)
    with open(PATH, "w", encoding="utf-8") as fh:
        fh.write(text)
    print(PATH)


if __name__ == "__main__":
    main()
