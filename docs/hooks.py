"""MkDocs hook: the reference pages generated at build time from nlcx's own code.

- ``reference/configuration.md``: every key of an experiment config (:class:`nlcx.config.ExperimentSection`
  and its nested sections), of a sweep (:class:`nlcx.sweeps.SweepSection`), the keys that compose
  files (``extends``, ``vars``) and every registered plugin's ``Params``/``Config`` model, each under
  its full dotted name with type, default, unit and description, read from the pydantic models
  (``model_fields``; the unit from ``json_schema_extra={"unit": ...}``), as definition lists, one
  heading per section.
- ``reference/cli.md``: every command of the ``nlcx`` Typer application with its usage, arguments and
  options.

Nothing here is written into ``docs/``: the pages exist only in the build (``mkdocs.yml``: ``hooks:``).
"""

from __future__ import annotations

import html
import inspect
import types
import typing
from collections.abc import Iterator
from typing import Any

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

#: Registry key -> (heading, the model attribute that validates a section of that kind, the dotted
#: prefix of its keys).
PLUGIN_KINDS = {
    "plants": ("Plants (`plant.name`, keys under `plant.params`)", "Params", "plant.params."),
    "controllers": ("Controllers (`controllers.<label>.kind`)", "Config", "controllers.<label>."),
    "schedules": (
        "Gain schedules (`controllers.<label>.loops.<loop>.schedule.kind`)",
        "Config",
        "controllers.<label>.loops.<loop>.schedule.",
    ),
    "uncertainties": ("Uncertainties and loop elements (`uncertainty.<label>.kind`)", "Config", "uncertainty.<label>."),
    "references": ("References (`reference.<signal>.kind`)", "Config", "reference.<signal>."),
    "tuners": ("Tuners (`controllers.<label>.tune[i].kind`)", "Config", "controllers.<label>.tune[i]."),
}

#: The keys that hold a kind's plugin sections: (key, type, description), listed under the kind's heading.
SECTION_KEYS = {
    "plants": [("plant.params", "mapping", "The parameters of the plant `plant.name` names, listed below.")],
    "controllers": [
        ("controllers.<label>", "mapping", "One controller; its `kind` names the model that validates it."),
        (
            "controllers.<label>.tune",
            "mapping | list[mapping]",
            "Tuners applied to the controller before it is built, in order ([tuners](#tuners)).",
        ),
    ],
    "uncertainties": [
        ("uncertainty.<label>", "mapping", "One uncertainty or loop element; `kind` defaults to the label.")
    ],
    "references": [("reference.<signal>", "mapping", "The reference of one output signal.")],
}

# --------------------------------------------------------------------------- configuration


def type_name(annotation: Any) -> str:
    """A field's type as a config author reads it: ``float``, ``"rk4" | "heun"``, ``dict[str, float]``."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if annotation is type(None):
        return "null"
    if origin is typing.Literal:
        return " \\| ".join(f"`{value!r}`".replace("'", '"') for value in args)
    if origin in (typing.Union, types.UnionType):
        return " \\| ".join(type_name(arg) for arg in args)
    if origin is typing.Annotated:
        return type_name(args[0])
    if origin is not None:
        inner = ", ".join("..." if arg is Ellipsis else type_name(arg) for arg in args)
        return f"{getattr(origin, '__name__', str(origin))}[{inner}]"
    if annotation is Any:
        return "any"
    if inspect.isclass(annotation) and issubclass(annotation, BaseModel):
        return "mapping"
    return getattr(annotation, "__name__", str(annotation))


def yaml_value(value: Any) -> str:
    """A default as YAML writes it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(yaml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {yaml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, BaseModel):
        return "(section)"
    return str(value)


def default_text(info: FieldInfo) -> str:
    """``required``, or the default value (a default factory is called)."""
    if info.is_required():
        return "required"
    if info.default_factory is not None:
        try:
            return f"`{yaml_value(info.default_factory())}`"  # type: ignore[call-arg]
        except TypeError:
            return "(computed)"
    if info.default is PydanticUndefined:
        return ""
    return f"`{yaml_value(info.default)}`"


def unit_of(info: FieldInfo) -> str:
    """The unit a field declares in ``json_schema_extra``, or nothing."""
    extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
    return str(extra.get("unit", ""))


def cell(text: str) -> str:
    """Text fit for one cell of a Markdown table (``<name>`` shown, not read as an HTML tag)."""
    return html.escape(" ".join(text.split()), quote=False).replace("|", "\\|")


def nested_models(annotation: Any, label: str = "name") -> Iterator[tuple[str, type[BaseModel]]]:
    """Pydantic models inside a field's type, with the key suffix they sit under
    (``""`` for the field itself, ``".<label>"`` for a mapping's values, ``"[i]"`` for a list's)."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if inspect.isclass(annotation) and issubclass(annotation, BaseModel):
        yield "", annotation
    elif origin in (typing.Union, types.UnionType):
        for arg in args:
            yield from nested_models(arg, label)
    elif origin is dict and len(args) == 2:
        for suffix, model in nested_models(args[1], label):
            yield f".<{label}>" + suffix, model
    elif origin in (list, tuple) and args:
        for suffix, model in nested_models(args[0], label):
            yield "[i]" + suffix, model


def key_entry(key: str, info: FieldInfo) -> str:
    """One key as a definition: its full dotted name, then its type, default and unit, then what it is."""
    facts = [type_name(info.annotation).replace("\\|", "|")]
    default = default_text(info)
    if default == "`(section)`":
        facts.append("optional")
    elif default:
        facts.append(default if default == "required" else f"default {default}")
    if unit_of(info):
        facts.append(f"unit {html.escape(unit_of(info), quote=False)}")
    description = html.escape(" ".join((info.description or "").split()), quote=False)
    return f"`{key}`\n:   {' · '.join(facts)}" + (f"\n\n    {description}" if description else "") + "\n"


def key_list(entries: list[str]) -> str:
    """Definitions of keys, in the block the stylesheet lays out (``docs/stylesheets/reference.css``)."""
    return '<div class="config-keys" markdown>\n\n' + "\n".join(entries) + "\n</div>\n"


def model_sections(model: type[BaseModel], prefix: str = "", level: int = 3) -> list[str]:
    """The keys of ``model`` under ``prefix``, then each section nested in it under a heading of its
    own (at ``level``) that names its full dotted key, recursively."""
    entries: list[str] = []
    nested: dict[str, type[BaseModel]] = {}
    for name, info in model.model_fields.items():
        key = f"{prefix}{info.alias or name}"
        entries.append(key_entry(key, info))
        label = name[:-1] if name.endswith("s") else "name"  # loops: <loop>
        for suffix, sub in nested_models(info.annotation, label):
            nested.setdefault(f"{key}{suffix}", sub)
    parts = [key_list(entries)] if entries else ["No keys.\n"]
    for key, sub in nested.items():
        parts.append(f"{'#' * level} `{key}`\n")
        parts += model_sections(sub, f"{key}.", level)
    return parts


def summary(obj: Any) -> str:
    """The first paragraph of ``obj``'s docstring, on one line."""
    doc = inspect.getdoc(obj) or ""
    return doc.split("\n\n")[0].replace("\n", " ")


def file_keys() -> str:
    """``extends`` and ``vars``: what a config file may hold besides the experiment, resolved before
    the experiment is validated (their descriptions are the JSON schema's, :mod:`nlcx.schema`)."""
    from nlcx.schema import experiment_schema

    properties = experiment_schema()["properties"]
    entries = []
    for key, kind in (("extends", "str | list[str]"), ("vars", "mapping")):
        description = html.escape(properties[key]["description"], quote=False)
        entries.append(f"`{key}`\n:   {kind} · optional\n\n    {description}\n")
    return key_list(entries)


def configuration_page() -> str:
    """The configuration reference: the experiment's sections, the sweep, the keys that compose a file,
    then every registered plugin, each key under its full dotted name."""
    from nlcx import registry
    from nlcx.config import ExperimentSection
    from nlcx.sweeps import SweepSection

    parts = [
        "# Configuration reference\n",
        "Generated from the pydantic models when the site is built, so it lists exactly the keys nlcx "
        "accepts, each under its full dotted name (the name an override such as `simulation.t_end=5` "
        "uses; `<label>` stands for a name you choose, `[i]` for a position in a list). A key a model "
        "does not declare is refused with a one-line error naming it. Units are SI unless a key says "
        "otherwise; angles are in rad.\n",
        "## Experiment\n",
        "The top level of an experiment YAML (`nlcx.config.ExperimentSection`). `controllers`, "
        "`uncertainty` and `reference` map labels to plugin sections, validated by the plugin their "
        "`kind` names ([below](#plugins)); `plant.params` is validated by the plant's parameter model.\n",
        *model_sections(ExperimentSection),
        "## Sweep\n",
        "The `sweep:` section of a sweep config (`nlcx sweep`; [the guide](../guide/sweeps.md)): the "
        "variants are the product grid × zip × random.\n",
        key_list(["`sweep`\n:   mapping · optional\n\n    The variants of a sweep (`nlcx sweep`); the keys below.\n"]),
        *model_sections(SweepSection, "sweep."),
        "## Composing files\n",
        "Resolved when the file is read, before the experiment is validated (`nlcx.config.read_config`); "
        'any value may also be a `"${dotted.key}"` string, replaced by a copy of that key\'s value.\n',
        file_keys(),
        "## Plugins\n",
        "The sections `controllers`, `uncertainty`, `reference` and `plant.params` hold, and the gain "
        "schedules and tuners inside a controller, by the registered plugin that validates them "
        "(`nlcx list KIND` lists them).\n",
    ]
    for kind, (heading, attribute, prefix) in PLUGIN_KINDS.items():
        parts.append(f"## {heading} {{ #{kind} }}\n")
        if kind in SECTION_KEYS:
            parts.append(
                key_list([f"`{k}`\n:   {kind_} · optional\n\n    {d}\n" for k, kind_, d in SECTION_KEYS[kind]])
            )
        for name in registry.ALL[kind].names():
            plugin = registry.ALL[kind].get(name)
            model = getattr(plugin, attribute, None)
            parts.append(f"### `{name}`\n")
            text = summary(plugin)
            if text:
                parts.append(text + "\n")
            if isinstance(model, type) and issubclass(model, BaseModel) and model.model_fields:
                parts += model_sections(model, prefix, level=4)
            else:
                parts.append("No keys.\n")
    return "\n".join(parts)


# --------------------------------------------------------------------------------- the CLI


def _param_type(param: Any) -> str:
    """A command parameter's type, from the annotation Typer keeps (click's type otherwise)."""
    descriptor = getattr(param, "type_descriptor", None)
    annotation = getattr(descriptor, "annotation", None)
    if annotation is not None:
        return type_name(annotation)
    return str(getattr(getattr(param, "type", None), "name", ""))


def _param_default(param: Any) -> str:
    """``required``, nothing for an empty or computed default, or the default value."""
    if param.required:
        return "required"
    default = param.default
    if default is None or callable(default) or default == () or default == []:
        return ""
    return f"`{yaml_value(default)}`"


def _usage(name: str, command: Any) -> str:
    """``nlcx NAME [OPTIONS] ARG [OPTIONAL]...``: the command's usage line."""
    pieces = [f"nlcx {name}"]
    if any(not _is_argument(p) for p in command.params):
        pieces.append("[OPTIONS]")
    for param in command.params:
        if _is_argument(param):
            metavar = param.name.upper()
            metavar = metavar if param.required else f"[{metavar}]"
            pieces.append(metavar + ("..." if param.nargs == -1 else ""))
    return " ".join(pieces)


def _is_argument(param: Any) -> bool:
    """Whether a parameter is positional (an argument), not an option."""
    return not getattr(param, "opts", [""])[0].startswith("-")


def _command_section(name: str, command: Any) -> str:
    """One command's section: its help, usage line, and tables of arguments and options."""
    text = html.escape(inspect.cleandoc(command.help or ""), quote=False)
    lines = [f"## `nlcx {name}`\n", text + "\n", f"```\n{_usage(name, command)}\n```\n"]
    arguments = [p for p in command.params if _is_argument(p)]
    options = [p for p in command.params if not _is_argument(p)]
    if arguments:
        lines.append("| argument | type | default | help |\n|---|---|---|---|")
        lines += [
            f"| `{p.name.upper()}` | {_param_type(p)} | {_param_default(p)} | {cell(getattr(p, 'help', '') or '')} |"
            for p in arguments
        ]
        lines.append("")
    if options:
        lines.append("| option | type | default | help |\n|---|---|---|---|")
        for p in options:
            names = ", ".join(f"`{o}`" for o in [*p.opts, *p.secondary_opts])
            kind = "flag" if getattr(p, "is_flag", False) else _param_type(p)
            repeat = " (repeatable)" if getattr(p, "multiple", False) else ""
            lines.append(f"| {names} | {kind}{repeat} | {_param_default(p)} | {cell(p.help or '')} |")
        lines.append("")
    return "\n".join(lines)


def cli_page() -> str:
    """The command-line reference, from the Typer application."""
    import typer

    from nlcx.cli import app
    from nlcx.cli.lazy import LazyCommand

    group = typer.main.get_command(app)
    parts = [
        "# Command-line reference\n",
        "Generated from the `nlcx` Typer application when the site is built; `nlcx COMMAND --help` "
        "prints the same. A configuration or input error is one line on stderr and exit status 2.\n",
        f"```\nnlcx [OPTIONS] COMMAND [ARGS]...\n```\n\n{inspect.cleandoc(group.help or '')}\n",
    ]
    top = [p for p in group.params if not _is_argument(p) and not getattr(p, "hidden", False)]
    if top:
        parts.append("| option | help |\n|---|---|")
        parts += [f"| {', '.join(f'`{o}`' for o in p.opts)} | {cell(p.help or '')} |" for p in top]
        parts.append("")
    for name, command in group.commands.items():  # type: ignore[attr-defined]
        if isinstance(command, LazyCommand):  # a thesis command: its options are its function's
            command = command.loaded
        if not command.hidden:
            parts.append(_command_section(name, command))
    return "\n".join(parts)


# -------------------------------------------------------------------------------- the hook


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add the generated reference pages to the site."""
    pages = {
        "reference/configuration.md": configuration_page(),
        "reference/cli.md": cli_page(),
    }
    for path, content in pages.items():
        files.append(File.generated(config, path, content=content))
    return files
