"""The ``translucent`` command line.

``main(argv=None) -> int``: 0 success (or within the threshold), 1 a check failed (metric
beyond its threshold, regression, unstable kernel), 2 bad usage or bad input, an output
that cannot be written (no permission, a full disk) included. Each
subcommand lives in its own module under :mod:`translucent.reports.commands` with two
functions, ``add_arguments(parser)`` and ``run(args) -> int``; the CLI is thin and the work
happens in the library.

Every command that prints results takes ``--no-progress``, ``--quiet`` and ``--json FILE``
(:mod:`translucent.reports.commands.record`).

``TRANSLUCENT_OPTIONS`` (environment) is split like a shell line and put before the
arguments of the command (after its name, and after the method or benchmark name of
``approx`` and ``bench``), so a CI suite can change behaviour in one place; an option given
on the command line wins over the same option from the environment.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import shlex
import sys

from .. import signals
from ..errors import InputError
from ..extras import missing_extra
from ..signals import Terminated
from .commands.record import add_common_options, json_target, quiet, write_record

__all__ = ["main", "COMMANDS"]

#: subcommand -> (module under translucent.reports.commands, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "doctor": ("doctor", "versions, Mitsuba variant, libLLVM, GPU and cache folder"),
    "scenes": ("scenes", "list the built-in scenes"),
    "profiles": ("profiles", "list the scattering profiles; describe one of a medium"),
    "render": ("render", "render a reference image of a scene with Mitsuba"),
    "references": ("references", "the built-in scenes' committed references: list, render"),
    "cache": ("cache", "the cache: size by kind, budget; prune or clear it"),
    "compare": ("compare", "compare a test image with a reference: metrics and error maps"),
    "approx": ("approx", "render a scene with a fast method"),
    "export": ("export", "write a scene for another renderer (Mitsuba 3 XML with meshes)"),
    "report": ("report", "the main job: fast methods against references, as an HTML report"),
    "bench": ("bench", "run-time-versus-error benchmarks"),
    "stress": ("stress", "numerical stability sweeps of every kernel"),
    "fit": ("fit", "fit dipole / SubEdit profiles to a captured slab image"),
    "capture": ("capture", "make a synthetic slab capture"),
    "capture-import": ("capture_import", "turn a photo of a lit slab into a capture (also "
                                         "spelt `capture import`)"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse exits 2 on usage errors, as we want
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}\n")


def _build_parser(chosen: str | None = None, *, every: bool = False) -> argparse.ArgumentParser:
    """Return the parser; only the ``chosen`` command's module is imported and given its options.

    The others are listed by name and help line: a command's module may import what only
    an extra of the install brings (:mod:`translucent.extras`), and ``compare`` must run
    without it. ``every``: every command with its options (for the tests of them all).
    """
    parser = _Parser(prog="translucent", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version",
                        version=f"translucent {importlib.import_module('translucent').__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, (module_name, help_text) in COMMANDS.items():
        if name != chosen and not every:
            sub.add_parser(name, help=help_text)
            continue
        try:
            module = importlib.import_module(f"translucent.reports.commands.{module_name}")
        except ModuleNotFoundError as error:
            if error.name == f"translucent.reports.commands.{module_name}":
                continue  # a command whose module is absent is left out
            raise
        command = sub.add_parser(name, help=help_text, description=module.__doc__)
        module.add_arguments(command)
        command.set_defaults(run=module.run)
    _add_common_options(parser)
    return parser


def _parser_or_missing_extra(chosen: str | None):
    """Return the parser of command ``chosen``; None (said why) when it lacks its extra."""
    try:
        return _build_parser(chosen)
    except ModuleNotFoundError as error:
        missing = missing_extra(error)
        if missing is None:
            raise
        print(f"translucent {chosen}: error: {missing}", file=sys.stderr)
        return None


def _chosen_command(argv: list[str]) -> str | None:
    """Return the command ``argv`` names (its first word that is one), or None."""
    return next((token for token in argv if token in COMMANDS), None)


def _add_common_options(parser: argparse.ArgumentParser) -> None:
    """Give every command (and sub-command) ``--no-progress``, ``--quiet`` and ``--json``."""
    choices = next((action.choices for action in parser._actions
                    if isinstance(action, argparse._SubParsersAction)), None)
    if choices:
        for command in choices.values():
            _add_common_options(command)
    else:
        add_common_options(parser)


@contextlib.contextmanager
def _progress_bars(shown: bool):
    """Hide every tqdm progress bar of the command while ``shown`` is False.

    The command's own ``--no-progress`` already hides its bars; this reaches those of the
    steps it calls (precomputations, renders) that take no such argument.
    """
    from ..progress import hidden as bars_hidden

    if shown:
        yield
        return
    from tqdm import std

    original = std.tqdm.__dict__["__init__"]

    def hidden(self, *args, **kwargs):
        kwargs["disable"] = True
        original.__get__(self, type(self))(*args, **kwargs)

    std.tqdm.__init__ = hidden
    try:
        with bars_hidden():
            yield
    finally:
        std.tqdm.__init__ = original


@contextlib.contextmanager
def _standard_output(silent: bool):
    """Send what the command prints on standard output nowhere while ``silent``."""
    if not silent:
        yield
        return
    with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
        yield


def _command_end(parser: argparse.ArgumentParser, argv: list[str]):
    """Return the index in ``argv`` just after the command's name(s) (``bench prt``: 2).

    And the parser of that (sub-)command, whose options :func:`_accepted_options` knows.
    """
    index = 0
    while True:
        choices = next((action.choices for action in parser._actions
                        if isinstance(action, argparse._SubParsersAction)), None)
        if not choices:
            return index, parser
        names = [i for i in range(index, len(argv)) if not argv[i].startswith("-")]
        if not names or argv[names[0]] not in choices:
            return index, parser
        index = names[0] + 1
        parser = choices[argv[names[0]]]


def _accepted_options(parser: argparse.ArgumentParser, options: list[str]):
    """Split ``TRANSLUCENT_OPTIONS`` into what the command accepts and what it does not.

    An option is a token starting with ``-`` (``--name`` or ``--name=value``) with the
    tokens that follow it up to the next option (its values). One the command has no
    such option for is left out, values and all, so that one variable can carry the
    options of several commands (``--no-progress`` for those that have it).
    """
    known = parser._option_string_actions
    groups: list[list[str]] = []
    for token in options:
        starts = token.startswith("-") and len(token) > 1 and not _is_number(token)
        if starts or not groups:
            groups.append([token])
        else:
            groups[-1].append(token)
    kept, ignored = [], []
    for group in groups:
        flag = group[0].split("=", 1)[0]
        accepted = not flag.startswith("-") or flag == "-" or flag in known
        (kept if accepted else ignored).extend(group)
    return kept, ignored


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


#: Options that do something else than run the command: never from TRANSLUCENT_OPTIONS,
#: where they would make every command of a CI job exit 0 having done nothing.
_NOT_FROM_ENVIRONMENT = ("-h", "--help", "--version")


class StandardOutputError(InputError):
    """Standard output cannot be written (a full device, a closed pipe)."""


class _CheckedOutput:
    """Standard output whose write errors end the command with one line, no traceback."""

    def __init__(self, stream):
        self._stream = stream

    def _checked(self, call, *args):
        try:
            return call(*args)
        except OSError as error:
            global _STANDARD_OUTPUT_FAILED
            _STANDARD_OUTPUT_FAILED = True
            raise StandardOutputError(f"cannot be written ({error.strerror or error})",
                                      field="standard output") from None

    def write(self, text):
        return self._checked(self._stream.write, text)

    def writelines(self, lines):
        return self._checked(self._stream.writelines, lines)

    def flush(self):
        return self._checked(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


#: Whether the last command met a standard output it could not write.
_STANDARD_OUTPUT_FAILED = False


@contextlib.contextmanager
def _checked_standard_output():
    """Route what the command prints through :class:`_CheckedOutput` for the block."""
    global _STANDARD_OUTPUT_FAILED
    _STANDARD_OUTPUT_FAILED = False
    original = sys.stdout
    sys.stdout = _CheckedOutput(original)
    try:
        yield
    finally:
        sys.stdout = original


def _on_sigterm(signum, frame):
    signals.record("terminate")
    if not signals.deferring():  # else raised by signals.check() at the next step
        raise Terminated()


def _on_sigint(signum, frame):
    signals.record("interrupt")
    if not signals.deferring():
        raise KeyboardInterrupt()


def _signal_behind(error: BaseException) -> BaseException | None:
    """Return the KeyboardInterrupt or Terminated that caused ``error``, if any.

    A signal that arrives while Mitsuba runs a Python plugin (a BSDF of ``brdf_plugins``)
    is raised in the plugin and reaches us wrapped in Dr.Jit's RuntimeError.
    """
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, (KeyboardInterrupt, Terminated)):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None


def _ended_by(error: BaseException, command: str) -> int | None:
    """Say in one line how ``error`` ended ``command``; return the exit code, None for a bug.

    A missing extra (2), an interrupt (130), SIGTERM (143), and a full disk, quota or
    read-only mount met where no writer of the command said so in its own words (2, as an
    output the writers cannot write is: :class:`~translucent.atomic.OutputError`).
    """
    from ..atomic import failed_file, output_failure

    missing = missing_extra(error)
    if missing is not None:
        print(f"translucent {command}: error: {missing}", file=sys.stderr)
        return 2
    signal_error = _signal_behind(error)
    if isinstance(signal_error, KeyboardInterrupt):
        print(f"translucent {command}: interrupted", file=sys.stderr)
        return 130
    if isinstance(signal_error, Terminated):
        print(f"translucent {command}: terminated", file=sys.stderr)
        return 143
    reason = output_failure(error)
    if reason is not None:
        where = failed_file(error)
        where = f"{where}: " if where else ""
        print(f"translucent {command}: error: {where}an output cannot be written ({reason})",
              file=sys.stderr)
        return 2
    return None


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code.

    Ctrl-C (SIGINT) and SIGTERM unwind the command, so that its temporary files are removed
    and nothing half-written is left, and end it with one line and exit code 130 / 143.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:2] == ["capture", "import"]:  # a verb of capture, a command of its own here
        argv = ["capture-import"] + argv[2:]
    text = os.environ.get("TRANSLUCENT_OPTIONS", "")
    try:
        options = shlex.split(text)
    except ValueError as error:
        print(f"translucent: error: TRANSLUCENT_OPTIONS = {text!r}: {error}", file=sys.stderr)
        return 2
    asked = [token for token in options if token.split("=", 1)[0] in _NOT_FROM_ENVIRONMENT]
    if asked:
        print(f"translucent: error: TRANSLUCENT_OPTIONS = {text!r}: {asked[0]} is asked for on "
              "the command line, not set for every command", file=sys.stderr)
        return 2
    parser = _parser_or_missing_extra(_chosen_command(argv))
    if parser is None:
        return 2
    end, command_parser = _command_end(parser, argv)
    if end and options:
        options, ignored = _accepted_options(command_parser, options)
        if ignored:
            print(f"translucent: note: TRANSLUCENT_OPTIONS {' '.join(ignored)!r} left out: "
                  f"'{command_parser.prog}' has no such option", file=sys.stderr)
    argv = argv[:end] + options + argv[end:]
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        if exit_.code and options:
            print(f"translucent: note: TRANSLUCENT_OPTIONS = {text!r} was put before the "
                  "command's arguments", file=sys.stderr)
        return int(exit_.code or 0)
    if not getattr(args, "run", None):
        parser.print_help()
        return 2
    import signal
    import threading

    previous = None
    if threading.current_thread() is threading.main_thread():
        signals.reset()
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
        previous_interrupt = signal.signal(signal.SIGINT, _on_sigint)
    from ..atomic import check_output_file, guarded_files
    from ..cache import check_settings

    try:
        # every output is compared with every input the command names (guarded_files)
        with guarded_files(), _checked_standard_output():
            check_settings()  # a bad cache setting is refused before any work
            target = json_target(args)
            if target not in (None, "-"):
                check_output_file(target, "--json", what="a file name for the JSON record")
            silent = quiet(args)
            with _progress_bars(not (silent or getattr(args, "no_progress", False))), \
                    _standard_output(silent):
                code = int(args.run(args) or 0)
            write_record(args, code)
            sys.stdout.flush()  # a full device or a closed pipe is found here, not at exit
        return code
    except InputError as error:
        print(f"translucent {args.command}: error: {error}", file=sys.stderr)
        return 2
    except BaseException as error:
        code = _ended_by(error, args.command)
        if code is None:
            raise
        return code
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
            signal.signal(signal.SIGINT, previous_interrupt)


#: Exit code of a command ended by a bug of the suite's own (an exception no check made).
INTERNAL_ERROR = 3

#: Set (to anything) to see the traceback of an internal error instead of its one line.
TRACEBACK_VARIABLE = "TRANSLUCENT_TRACEBACK"


def _internal_error(error: Exception, argv) -> int:
    """Say in one line that a bug ended the command; return :data:`INTERNAL_ERROR`."""
    command = next((word for word in argv if not word.startswith("-")), "")
    print(f"translucent{' ' + command if command else ''}: internal error, a bug in "
          f"translucent ({type(error).__name__}: {error}); {TRACEBACK_VARIABLE}=1 shows its "
          "traceback", file=sys.stderr)
    return INTERNAL_ERROR


def entry_point() -> None:
    """Run :func:`main` as the ``translucent`` program and exit with its code.

    :func:`main` lets a bug's exception through (the files of the command are already
    removed as it unwinds); here, for a user, it becomes one line and exit code
    :data:`INTERNAL_ERROR`, or the traceback with ``TRANSLUCENT_TRACEBACK`` set.
    """
    try:
        code = main()
    except Exception as error:
        if os.environ.get(TRACEBACK_VARIABLE):
            raise
        code = _internal_error(error, sys.argv[1:])
    if _STANDARD_OUTPUT_FAILED:
        # what is still buffered for it would fail again at exit, with a second message
        with contextlib.suppress(OSError, ValueError):
            sink = os.open(os.devnull, os.O_WRONLY)
            os.dup2(sink, sys.stdout.fileno())
    if code in (130, 143):
        # a render cut short inside a Dr.Jit kernel can leave its thread pool waiting at
        # interpreter shutdown; the command has already unwound and removed its files
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry_point()
