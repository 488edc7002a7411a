"""Every error code mpgspec reports, with what it means and how to fix it: `mpgspec explain CODE`
and docs/error-codes.md (written from this table; a test keeps both and the source in step).

Codes: MPG0xx the command line and the run, MPG1xx spec structure and values, MPG2xx expressions,
MPG3xx references between specs and compiling them, MPG4xx report files, MPG9xx internal errors.
"""
from __future__ import annotations

CODES: dict[str, tuple[str, str]] = {
    "MPG000": ("an mpgspec error", "The generic code of an error no more specific code covers; the message says "
               "what happened."),
    "MPG001": ("wrong usage", "The command line or the Python API was called wrongly: a path that does not exist, "
               "an option out of range, an unknown primitive name (the message suggests the nearest one). Fix the "
               "command; `mpgspec COMMAND --help` lists the options with examples."),
    "MPG002": ("interrupted", "The run was stopped by Ctrl-C or a signal. Reports are written atomically, so no "
               "half-written file is left; stored oracle results are kept and the next run reuses them."),
    "MPG100": ("invalid spec", "A spec file is not valid YAML, cannot be read, or breaks a rule no more specific "
               "code covers. The message names file:line, the key, what was expected and what was found."),
    "MPG101": ("duplicate key", "A mapping in a spec file names the same key twice; YAML would silently keep the "
               "last one. Remove or rename one of them."),
    "MPG102": ("unknown key", "A key the spec format does not have (often a typo; the hint names the nearest valid "
               "key). `mpgspec schema` prints the JSON Schema an editor can check against."),
    "MPG103": ("missing key", "A required key is absent, e.g. a primitive without `name` or `controller`."),
    "MPG104": ("invalid value", "A value has the wrong type or is out of range: a negative dt, a horizon that is "
               "not finite, a string where a number is expected, a name that cannot be a folder."),
    "MPG105": ("name clash", "A declared name (a state, input, parameter, argument or `let`) is not an "
               "identifier, appears twice, or would hide a state, input, parameter, setpoint symbol, built-in "
               "constant (pi, e, inf), function, keyword or t/s. Rename it."),
    "MPG106": ("unknown joint or foot", "A robot controller names a joint or foot the system's model does not "
               "have. Use the names of the URDF (the message lists them)."),
    "MPG107": ("unknown uncertainty reference", "The `uncertainty` block names a parameter, input or state the "
               "system does not have."),
    "MPG108": ("a feature needs something the spec lacks", "E.g. a window anchored on a contact event needs "
               "contact events in the state; the MuJoCo cross-check needs a `sequence`, its velocity noise a "
               "floating base. The hint says what to add."),
    "MPG109": ("robot model not loadable", "The URDF of a rigid-body system cannot be read or built by Pinocchio "
               "(missing file, malformed XML, unsupported joint). The message gives the model's own error."),
    "MPG110": ("gait table missing or stale", "A trot primitive's gait table (written by `mpgspec gait`) is absent, "
               "malformed or was generated for other parameters. Run `mpgspec gait GAITS.yaml` again."),
    "MPG111": ("LQR design failed", "The linearisation at the setpoint is not stabilisable with the given Q and R "
               "(or not finite). Check the setpoint, the weights and the input matrix."),
    "MPG120": ("unknown oracle method", "`oracle.method` (or --method) names a backend that is not installed. "
               "Built in: rk4 and scipy; plug-ins add more."),
    "MPG121": ("optional extra not installed", "A feature needs an extra that is not installed, e.g. the MuJoCo "
               "cross-check: `pip install mpgspec[xcheck]`."),
    "MPG200": ("invalid expression", "An expression in a spec does not parse or cannot be used; a more specific "
               "MPG2xx code usually applies."),
    "MPG201": ("expression syntax", "A malformed number, an unexpected character or an unbalanced parenthesis; "
               "the caret marks the position."),
    "MPG202": ("unknown function", "The expression calls a function the expression language does not have "
               "(sin, cos, sqrt, exp, min, max, abs, sat, if_else, ... are available)."),
    "MPG203": ("wrong number of arguments", "A function is called with too many or too few arguments."),
    "MPG204": ("unknown name", "The expression names something that is neither a state, an input, a parameter, "
               "a constant nor a time variable of the primitive."),
    "MPG205": ("expression cannot be evaluated", "A constant expression divides by zero, overflows or evaluates to "
               "NaN, or a safety function is not finite at the setpoint."),
    "MPG206": ("not a number", "An expression where one number is expected gives a vector or another non-scalar."),
    "MPG207": ("expression too deep", "Parentheses, calls or signs are nested deeper than the parser accepts; "
               "split the expression or use a parameter."),
    "MPG300": ("cannot compile", "A valid spec could not be compiled to CasADi (e.g. a singular linearisation)."),
    "MPG301": ("included file unreadable", "A file the spec names (a primitive, a system, a table) is missing, "
               "unreadable or holds no YAML mapping. Paths are relative to the project file."),
    "MPG302": ("unknown safe-set block", "A primitive's `safe_set` uses a block that `safe_sets` does not define."),
    "MPG303": ("duplicate primitive", "Two primitives (or two argument values of one) share a name."),
    "MPG304": ("unknown primitive", "An assertion, a `next`, the sequence or the uncertainty block names a "
               "primitive the project does not have (the message lists the names)."),
    "MPG305": ("file outside the project", "A spec names a file outside the project folder; allow its folder with "
               "--allow-path DIR if that is intended."),
    "MPG306": ("transients in a cycle", "Transient primitives hand over to each other in a cycle; a chain of "
               "transients must end in a fixed or periodic primitive."),
    "MPG400": ("reports not written", "The report files could not be written (a read-only folder, a full disk, a "
               "project name that would land outside the report folder). Nothing else of the run is lost."),
    "MPG410": ("report refused", "A report.json that plan, simulate or diff cannot use: edited since `mpgspec "
               "verify` wrote it, written with another key, or malformed. Verify again, or pass --rebuild."),
    "MPG900": ("internal error", "A bug in mpgspec, not a mistake in the spec. Set MPGSPEC_DEBUG=1 for the "
               "traceback and report it with the spec that triggers it."),
}


def explain(code: str) -> str | None:
    """The text `mpgspec explain` prints for a code (MPG104, mpg104 or 104), None when unknown."""
    key = str(code).strip().upper()
    key = key if key.startswith("MPG") else "MPG" + key.zfill(3)
    if key not in CODES:
        return None
    title, text = CODES[key]
    return f"{key}: {title}\n\n{text}"


def markdown() -> str:
    """docs/error-codes.md: every code with its title and explanation."""
    lines = ["# Error codes", "",
             "Every error mpgspec reports carries one of these codes; `mpgspec explain CODE` prints its entry.",
             "Exit codes: 0 every check holds, 1 a check failed, 2 a spec or usage error (any code below).", "",
             "| code | what | meaning and fix |", "|---|---|---|"]
    lines += [f"| {c} | {t} | {x} |" for c, (t, x) in CODES.items()]
    return "\n".join(lines) + "\n"
