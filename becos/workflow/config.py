"""The configuration: ``becos/data/schema.yaml`` checked and defaults filled in (then ``remesher: auto``
resolved and the checks across keys run by :mod:`becos.workflow.options`), config files read with errors
that name the file, line and fix."""

from __future__ import annotations

from copy import deepcopy
from pathlib import Path

from becos.defaults import SCHEMA_PATH, config_schema
from becos.errors import ConfigError

__all__ = ["SCHEMA_PATH", "resolve_config", "schema_problems", "load_config", "read_config_file", "check_config_files"]


def _typed_command_line_values(schema: dict, instance):
    """Values given on the command line arrive as strings where Snakemake does not type them (inside a
    mapping such as ``--config 'caps={train: 2, val: null}'`` it reads them with YAML's BaseLoader): a
    string where the schema admits no string is read as a YAML scalar (:func:`_scalar_from_text`) and
    kept when the result has a type the schema admits, recursively; anything else is left to the schema
    (and its one-line error)."""
    kind = schema.get("type")
    if isinstance(instance, dict) and kind == "object":
        props = schema.get("properties", {})
        return {k: _typed_command_line_values(props[k], v) if k in props else v for k, v in instance.items()}
    if isinstance(instance, list) and kind == "array" and isinstance(schema.get("items"), dict):
        return [_typed_command_line_values(schema["items"], v) for v in instance]
    if isinstance(instance, str):
        return _scalar_from_text(schema, instance)
    return instance


def _scalar_from_text(schema: dict, text: str):
    """``text`` read as a YAML scalar (``'2'`` -> 2, ``'null'`` -> None, ``'true'`` -> True) when ``schema``
    admits no string but admits the value read; else ``text`` unchanged. A number such as ``'1e-3'``, which
    YAML 1.1 reads as a string, is read with ``float`` where the schema admits a number."""
    import yaml

    wanted = schema.get("type")
    wanted = [wanted] if isinstance(wanted, str) else list(wanted or [])
    if not wanted or "string" in wanted:
        return text
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    if isinstance(value, (dict, list)) or not _accepts_type(schema, value):
        if "number" not in wanted:
            return text
        try:
            return float(text)
        except ValueError:
            return text
    return value


def _fill_defaults(schema: dict, instance):
    """Fill ``default`` values of object properties, recursively (like Snakemake's ``validate``)."""
    if not isinstance(instance, dict) or schema.get("type") != "object":
        return instance
    for key, sub in schema.get("properties", {}).items():
        if key not in instance and "default" in sub:
            instance[key] = deepcopy(sub["default"])
        if key in instance:
            _fill_defaults(sub, instance[key])
    return instance


def resolve_config(raw: dict) -> dict:
    """Validate ``raw`` against ``becos/data/schema.yaml``, fill defaults, check what a schema cannot.

    Raises:
        ConfigError: one line per problem (:func:`schema_problems`, :func:`becos.workflow.options.check_config`), each
            ``<key>: <what is wrong>. Fix: <fix>`` (unknown key, wrong type, reversed overlap range, ...).
    """
    import jsonschema

    from becos.workflow.options import check_config, resolve_remesher, switch_off_exports

    schema = config_schema()
    config = _fill_defaults(schema, _typed_command_line_values(schema, deepcopy(dict(raw))))
    resolve_remesher(config)
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: [str(k) for k in e.absolute_path])
    if errors:
        raise ConfigError("\n".join(line for e in errors for line in schema_problems(e)))
    switch_off_exports(config, schema)
    check_config(config)
    return config


CONFIG_DOCS = "config/README.md"
_TYPE_NAMES = {
    "integer": "an integer",
    "number": "a number",
    "string": "a string",
    "boolean": "true or false",
    "array": "a list",
    "object": "a mapping (key: value)",
    "null": "null",
}


def _key(path) -> str:
    """A config key path as the user writes it: ``caps.train``, ``datasets[1]``, ``(top level)``."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or "(top level)"


def _type_of(value) -> str:
    """The JSON-schema type name of a YAML value."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    return {float: "number", str: "string", list: "array", dict: "object"}.get(type(value), type(value).__name__)


def _accepts_type(schema: dict, value) -> bool:
    """Whether ``schema``'s ``type`` (if any) admits ``value``."""
    wanted = schema.get("type")
    if wanted is None:
        return True
    wanted = [wanted] if isinstance(wanted, str) else list(wanted)
    kind = _type_of(value)
    return kind in wanted or (kind == "integer" and "number" in wanted)


def schema_problems(error) -> list[str]:
    """One line per problem of a jsonschema ``ValidationError``: ``<key>: <what is wrong>. Fix: <fix>``.

    ``oneOf``/``anyOf`` errors report the branch whose type fits the value (e.g. a bad ``sha256`` inside
    ``annotations_archive``), or the allowed forms when none fits.
    """
    import difflib

    key, value, rule, limit = _key(error.absolute_path), error.instance, error.validator, error.validator_value
    docs = f"see {CONFIG_DOCS}"
    if rule == "additionalProperties":
        known = sorted(error.schema.get("properties", {}))
        lines = []
        for extra in sorted(set(value) - set(known), key=str):
            name = _key([*error.absolute_path, extra])
            close = difflib.get_close_matches(str(extra), known, n=1)
            if close:
                fix = f"did you mean '{close[0]}'? Correct the spelling or remove the key ({docs})"
            elif len(known) <= 12:
                fix = f"remove it; the keys here are {', '.join(known)} ({docs})"
            else:
                fix = f"remove it (every key: {CONFIG_DOCS})"
            lines.append(f"{name}: unknown key. Fix: {fix}")
        return lines
    if rule == "type":
        wanted = [limit] if isinstance(limit, str) else list(limit)
        expected = " or ".join(_TYPE_NAMES.get(t, t) for t in wanted)
        return [
            f"{key}: {value!r} is {_TYPE_NAMES.get(_type_of(value), _type_of(value))}, not {expected}. "
            f"Fix: give {expected} ({docs})"
        ]
    if rule == "enum":
        choices = ", ".join(map(str, limit))
        close = difflib.get_close_matches(str(value), [str(c) for c in limit], n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        return [f"{key}: {value!r} is not an allowed value. Fix: use one of {choices}{hint}"]
    bounds = {
        "minimum": ("below the minimum", ">="),
        "exclusiveMinimum": ("not above", ">"),
        "maximum": ("above the maximum", "<="),
        "exclusiveMaximum": ("not below", "<"),
    }
    if rule in bounds:
        what, op = bounds[rule]
        return [f"{key}: {value!r} is {what} {limit}. Fix: use a value {op} {limit}"]
    if rule == "minItems":
        return [f"{key}: the list has {len(value)} item(s), it needs at least {limit}. Fix: list at least {limit}"]
    if rule == "maxItems":
        return [f"{key}: the list has {len(value)} items, at most {limit} are allowed. Fix: shorten it"]
    if rule == "uniqueItems":
        repeated = sorted({str(v) for v in value if value.count(v) > 1})
        return [f"{key}: lists {', '.join(repeated)} more than once. Fix: list each item once"]
    if rule == "minLength":
        return [f"{key}: is empty. Fix: give a non-empty value ({docs})"]
    if rule == "pattern":
        return [f"{key}: {value!r} does not have the expected form (pattern {limit}). Fix: {docs}"]
    if rule == "required":
        missing = [k for k in limit if k not in value]
        return [f"{_key([*error.absolute_path, k])}: missing. Fix: add it ({docs})" for k in missing]
    if rule in ("oneOf", "anyOf") and error.context:
        branches = error.schema.get(rule, [])
        fitting = [i for i, b in enumerate(branches) if _accepts_type(b, value)]
        if len(fitting) == 1:
            inner = [e for e in error.context if e.relative_schema_path and e.relative_schema_path[0] == fitting[0]]
            lines = [line for e in inner for line in schema_problems(e)]
            if lines:
                return lines
        kinds = [t for b in branches for t in ([b["type"]] if isinstance(b.get("type"), str) else b.get("type", []))]
        forms = " or ".join(_TYPE_NAMES.get(t, t) for t in kinds) or "another form"
        return [f"{key}: {value!r} is {_TYPE_NAMES.get(_type_of(value), _type_of(value))}. Fix: give {forms} ({docs})"]
    message = " ".join(str(error.message).split())
    return [f"{key}: {message}. Fix: {docs}"]


def load_config(path: str | Path) -> dict:
    """Read a config (JSON or YAML) and resolve it (:func:`resolve_config`)."""
    return resolve_config(read_config_file(path))


def read_config_file(path: str | Path) -> dict:
    """The mapping in a YAML (or JSON) config file, unresolved.

    Raises:
        ConfigError: ``<file>: <problem>. Fix: <fix>`` when the file is missing, is not valid YAML (with
            its line and column) or does not hold a mapping.
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "not found"
        raise ConfigError(
            f"{path}: config file {what} ({path.absolute()}). Fix: check the path given to "
            "--configfile (keys: config/README.md; an example: config/tosca.yaml)"
        )
    try:
        value = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark, start = getattr(exc, "problem_mark", None), getattr(exc, "context_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
        if start is not None and getattr(exc, "context", None):
            problem += f"; {exc.context} at line {start.line + 1}, column {start.column + 1}"
        raise ConfigError(
            f"{path}: {where}not valid YAML ({problem}). Fix: correct the YAML syntax there "
            "(e.g. a missing ']' or ':', tabs used for indentation)"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot be read ({exc}). Fix: check the file's permissions and encoding") from None
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(
            f"{path}: holds {type(value).__name__}, not a mapping of config keys. "
            "Fix: write one `key: value` per line (config/README.md)"
        )
    return value


def check_config_files(argv: list[str]) -> list[str]:
    """Problems (one line each) of the ``--configfile``/``--configfiles`` files named in a Snakemake
    command line: missing, not YAML, not a mapping. Snakemake itself reports these with a traceback or
    without file and line, before the workflow is read (the default workflow profile calls this)."""
    files, taking = [], False
    for arg in argv:
        name, eq, value = arg.partition("=")
        if name in ("--configfile", "--configfiles"):
            taking = not eq  # `--configfile a.yaml b.yaml` (nargs +) or `--configfile=a.yaml`
            if eq:
                files.append(value)
        elif taking and not arg.startswith("-"):
            files.append(arg)
        else:
            taking = False
    problems = []
    for name in files:
        try:
            read_config_file(name)
        except ConfigError as exc:
            problems.append(str(exc))
    return problems
