"""The ``fbia`` command line: a thin layer over :func:`fbia.load_study` and the registry.

::

    fbia validate study.toml                  check everything that needs no forward run
    fbia forward study.toml --set E=400 --set nu=0.3 [--output DIR]
    fbia run study.toml [--workers N] [--output DIR] [--fresh] [--retry-failed]
                        [--reuse-changed-code] [--address tcp://HOST:PORT]
    fbia plugins [--json] [--options NAME]   NAME's options: default, unit, description
    fbia schema                               the JSON Schema of a study file (for editors)
    fbia reproductions OUT.md DIR [DIR ...]   the summary of the paper.json files below DIRs
    fbia --version

``fbia run`` on an output folder that holds a study store resumes the study: every stored run
of the same problem is reused, none is run again; ``--fresh`` starts over, ``--retry-failed``
runs stored failures again, ``--address`` sends the runs to a running Dask scheduler.  A store
whose runs were made by other code of the model plugin (its source files changed) is refused
unless ``--reuse-changed-code`` says the change leaves the results as they were.

Exit status: 0 done (``fbia run``: the result is a success and not flagged ``unreliable`` or
``unchecked``); 3 ``fbia run`` wrote a result that is not trustworthy (not converged, flagged
``unreliable`` or ``unchecked``: its report says why); 4 ``fbia run`` wrote no result (every
forward run failed, no start or noise draw gave an estimate); 1 a forward run failed
(``fbia forward``, or ``fbia run`` without an iterator),
a file could not be written, or the study store could not be read or written (a full disk, a
read-only or damaged store: one line naming the file and what to do); 2 bad input (study
file, data files, plugin names, options, arguments; a store made for a different problem):
one line ``fbia: error: <message>`` on stderr, no traceback;
130 interrupted by Ctrl-C, 143 terminated by SIGTERM (a batch system's wall-time limit), both
after saving what was computed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NoReturn

from ..core.errors import ConfigError, Terminated

if TYPE_CHECKING:
    from ..core.problem import Result

PROG = "fbia"

#: exit statuses of the command line (the module docstring says when each is given)
EXIT_OK = 0
EXIT_ERROR = 1
EXIT_BAD_INPUT = 2
EXIT_UNTRUSTED = 3
EXIT_NO_RESULT = 4
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143
#: result statuses that a success may still carry but that make it untrustworthy
UNTRUSTED_STATUSES = frozenset({"unreliable", "unchecked"})
#: result statuses that mean "no estimate at all"
NO_RESULT_STATUSES = frozenset({"all_failed", "no_result"})


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr and exit status 2."""

    def error(self, message: str) -> NoReturn:
        command = self.prog.removeprefix(PROG).strip()
        raise _UsageError(f"{command}: {message}" if command else message)


class _UsageError(Exception):
    pass


def _parser() -> argparse.ArgumentParser:
    from ..core.version import __version__

    p = _Parser(
        prog=PROG,
        description="Calibrate biofilm models from the shape of the fluid-biofilm interface.",
    )
    p.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    change = (
        "a change of the study file after the files it extends are merged (repeatable): "
        "section.key=value, the value in TOML (e.g. iterator.options.seed=3, "
        "parameters.0.bounds=[100.0,900.0])"
    )
    v = sub.add_parser("validate", help="check a study file without running the model")
    v.add_argument("study", metavar="FILE", help="study file (TOML)")
    v.add_argument(
        "--set", dest="changes", action="append", default=[], metavar="KEY=VALUE", help=change
    )

    f = sub.add_parser("forward", help="one forward run and its discrepancy table")
    f.add_argument("study", metavar="FILE", help="study file (TOML)")
    f.add_argument(
        "--set",
        dest="values",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a parameter value (repeatable; default: 'initial', else mid-bounds), or with a "
        "dotted name section.key=value " + change[0].lower() + change[1:],
    )
    f.add_argument(
        "--output", metavar="DIR", type=_folder, help="output folder (default: <output>/forward)"
    )

    r = sub.add_parser("run", help="run the study and write its output folder")
    r.add_argument("study", metavar="FILE", help="study file (TOML)")
    r.add_argument(
        "--set", dest="changes", action="append", default=[], metavar="KEY=VALUE", help=change
    )
    r.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes (overrides [executor]; 1 runs serially)",
    )
    r.add_argument(
        "--output", metavar="DIR", type=_folder, help="output folder (default: the study's)"
    )
    r.add_argument(
        "--fresh",
        action="store_true",
        help="start over: delete the study store and run folders of the output folder",
    )
    r.add_argument(
        "--retry-failed",
        action="store_true",
        help="run the stored failed runs again instead of reusing their failure",
    )
    r.add_argument(
        "--reuse-changed-code",
        action="store_true",
        help="reuse the stored runs although the model plugin's source changed since they "
        "were made (only when the change leaves the results as they were)",
    )
    r.add_argument(
        "--address",
        metavar="TCP",
        help="run on the Dask scheduler at this address (overrides [executor])",
    )
    r.add_argument(
        "--log-level",
        choices=("info", "debug"),
        default="info",
        help="what fbia.log records: info (batches, runs, store, GP fits, design checks, "
        "SMC summaries) or debug (also every run's start, tempering steps, design rounds)",
    )

    rp = sub.add_parser(
        "reproductions",
        help="summarise the comparisons with the papers (paper.json below the folders)",
    )
    rp.add_argument("summary", metavar="OUT", help="the markdown page to write")
    rp.add_argument("folders", metavar="DIR", nargs="+", help="folders to search")

    sub.add_parser("schema", help="print the JSON Schema of a study file (for editors)")
    it = sub.add_parser("init", help="write a commented template study for a model")
    it.add_argument("study", metavar="FILE", nargs="?", default="study.toml", help="to write")
    it.add_argument("--model", required=True, metavar="NAME", help="forward model plugin")
    it.add_argument(
        "--iterator", default="levenberg_marquardt", metavar="NAME", help="iterator plugin"
    )
    it.add_argument("--measure", default="ray", metavar="NAME", help="measure plugin")
    it.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing FILE (a regular file: links and FIFOs are refused)",
    )
    pl = sub.add_parser("plugins", help="list the installed forward models, measures, iterators")
    pl.add_argument("--json", action="store_true", help="print JSON instead of a table")
    pl.add_argument(
        "--options",
        metavar="NAME",
        help="every option of the plugin NAME: default, unit and description",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (the console script exits with it)."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    try:
        try:
            args = _parser().parse_args(args_list)
        except SystemExit as exc:  # --help, --version
            return exc.code if isinstance(exc.code, int) else 0
        if args.command is None:
            _parser().print_help()
            return 2
        _terminate_like_ctrl_c()
        command = {
            "validate": _validate,
            "forward": _forward,
            "run": _run,
            "plugins": _plugins,
            "reproductions": _reproductions,
            "schema": _schema,
            "init": _init,
        }[args.command]
        return command(args)
    except _UsageError as exc:
        return _fail(str(exc), 2)
    except ConfigError as exc:  # includes PluginError
        return _fail(str(exc), 2)
    except Terminated:
        print(f"{PROG}: terminated (SIGTERM); what was computed is saved", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; what was computed is saved", file=sys.stderr)
        return 130
    except MemoryError:
        return _fail(
            "out of memory (lower the sizes in the study file); what was computed is saved", 1
        )
    except OSError as exc:  # e.g. an output folder that cannot be written
        return _fail(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc), 1)


def _folder(text: str) -> str:
    """An ``--output`` folder: not empty (which would write into the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("needs a folder name, got an empty one")
    return text


def _terminate_like_ctrl_c() -> None:
    """SIGTERM raises :class:`~fbia.core.errors.Terminated` (a KeyboardInterrupt): the study
    stops its workers and saves what was computed, as on Ctrl-C."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends at once
        raise Terminated

    signal.signal(signal.SIGTERM, handler)


def _fail(message: str, status: int) -> int:
    print(f"{PROG}: error: {' '.join(message.split())}", file=sys.stderr)
    return status


def _load(args: argparse.Namespace, build: bool = True) -> Any:
    from .study_file import load_study

    return load_study(args.study, build=build, overrides=getattr(args, "changes", ()))


def _validate(args: argparse.Namespace) -> int:
    study = _load(args, build=False)
    _check_units(study)
    print(study.summary())
    print("ok")
    return 0


def _check_units(study: Any) -> None:
    """The study's units (:mod:`fbia.studies.sanity`): the first mistake no study can mean
    is a ConfigError (exit 2), the other suspicions are one ``warning:`` line each."""
    from .sanity import unit_errors, unit_warnings

    errors = unit_errors(study)
    if errors:
        raise errors[0]
    for line in unit_warnings(study):
        print(f"{PROG}: warning: {study.file}: {line}", file=sys.stderr)


def _parse_values(items: Sequence[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise ConfigError(f"expected NAME=VALUE, got {item!r}", "--set")
        try:
            value = float(text)
        except ValueError:
            raise ConfigError(f"value of {name!r} is not a number: {text!r}", "--set") from None
        if not math.isfinite(value):
            raise ConfigError(f"value of {name!r} is not finite: {text!r}", "--set")
        out[name] = value
    return out


def _forward(args: argparse.Namespace) -> int:
    # a dotted name changes the study file (as run's --set), a plain one is a parameter's value
    args.changes = [item for item in args.values if "." in item.partition("=")[0]]
    values = _parse_values([item for item in args.values if item not in args.changes])
    study = _load(args)
    study.start_point(values)  # unknown names are user errors before anything runs
    from .runner import forward_study

    result = forward_study(study, values, args.output)
    if not result.success:
        return _fail(result.message, 1)
    return 0


def _run(args: argparse.Namespace) -> int:
    study = _load(args, build=False)
    _check_units(study)
    _ = study.problem  # the synthetic observations' forward runs, once the units are right
    from .runner import run_study

    result = run_study(
        study,
        args.output,
        args.workers,
        fresh=args.fresh,
        retry_failed=args.retry_failed,
        address=args.address,
        reuse_changed_code=args.reuse_changed_code,
        log_level=args.log_level,
    )
    if study.iterator is None and not result.success:
        return _fail(result.message, 1)
    status = run_exit_status(result)
    what = {EXIT_UNTRUSTED: "the result is not trustworthy", EXIT_NO_RESULT: "no result"}
    if status in what:
        print(
            f"{PROG}: {what[status]} (status {result.status}): "
            f"{' '.join(result.message.split())} (exit status {status})",
            file=sys.stderr,
        )
    return status


def run_exit_status(result: Result) -> int:
    """The exit status of ``fbia run`` for its result: :data:`EXIT_OK` only for a result that
    is a success and not flagged ``unreliable`` or ``unchecked``; :data:`EXIT_NO_RESULT` when
    there is no estimate (every run failed, no start or draw gave one); :data:`EXIT_UNTRUSTED`
    for the rest (a result that ran but did not converge or is flagged)."""
    if result.success and result.status not in UNTRUSTED_STATUSES:
        return EXIT_OK
    if result.status in NO_RESULT_STATUSES or (result.x is None and not result.success):
        return EXIT_NO_RESULT
    return EXIT_UNTRUSTED


def _reproductions(args: argparse.Namespace) -> int:
    from .paper_report import write_summary

    path, n = write_summary(args.summary, args.folders)
    print(f"{path}: {n} studies")
    return 0


def _schema(args: argparse.Namespace) -> int:
    from .study_file import SECTIONS
    from .study_schema import study_json_schema

    print(json.dumps(study_json_schema(SECTIONS), indent=1, default=str))
    return 0


def _init(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .study_template import study_template

    path = Path(args.study)
    if path.is_symlink():  # a dangling one too: the template would land where it points
        raise ConfigError("is a symbolic link: not written through; give another FILE", str(path))
    if path.exists() and not path.is_file():  # a FIFO would block the write, a device ...
        raise ConfigError("exists and is not a regular file; give another FILE", str(path))
    if path.exists() and not args.force:
        raise ConfigError("exists already; give another FILE or --force to overwrite", str(path))
    name = "".join(c if c.isalnum() or c in "_-" else "_" for c in path.stem) or "my_study"
    text = study_template(args.model, args.iterator, args.measure, name=name)
    # O_NOFOLLOW, O_NONBLOCK: a link or FIFO put there since is refused, never waited on
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_NONBLOCK
    with os.fdopen(os.open(path, flags, 0o666), "w", encoding="utf-8") as file:
        file.write(text)
    print(f"wrote {path}; next: {PROG} validate {path}, then {PROG} run {path}")
    return 0


def _plugins(args: argparse.Namespace) -> int:
    from ..core.registry import list_plugins

    if args.options is not None:
        return _plugin_options(args.options, args.json)
    rows = [e.describe() for e in list_plugins()]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    from .tables import format_table

    columns = ["name", "kind", "distribution", "version", "class"]
    if any(r["missing"] for r in rows):  # a plugin whose extra is not installed: say which
        columns.append("missing")
    print(format_table(rows, columns))
    return 0


def _plugin_options(name: str, as_json: bool) -> int:
    """``fbia plugins --options NAME``: the options of every plugin called NAME."""
    from ..core.registry import close_name, list_plugins
    from .tables import format_table

    entries = [e for e in list_plugins() if e.name == name]
    if not entries:
        names = sorted({e.name for e in list_plugins()})
        close = close_name(name, names)
        hint = f"; did you mean {close}?" if close else f"; installed: {', '.join(names)}"
        raise ConfigError(f"no plugin named {name!r}{hint}", "--options")
    described = {}
    for e in entries:
        described[e.kind] = e.factory.Options.describe()
    if as_json:
        print(json.dumps(described, indent=1, default=str))
        return 0
    for kind, options in described.items():
        print(f"{kind} {name}: {len(options)} option{'s' if len(options) != 1 else ''}")
        rows = [
            {**v, "option": k, "default": json.dumps(v["default"], default=str)}
            for k, v in options.items()
        ]
        if rows:
            print(format_table(rows, ["option", "default", "unit", "description"]))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
