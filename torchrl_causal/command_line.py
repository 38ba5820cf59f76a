"""``key=value`` arguments of the command lines, typed and checked, and one-line errors.

Every command line but ``train`` (which Hydra parses against the config schema) declares
its arguments as :class:`Option` s; :func:`parse_arguments` answers ``--help`` (``-h``,
``help``) with the command's help (:func:`help_text`: what it does, each option with its
default, one example) and exit status 0, and refuses an unknown, missing or repeated
argument with the command's usage line and a value of the wrong type or out of range with
one line naming it, before anything is read or written. :func:`one_line_errors` turns the
faults a user can cause and fix (a missing or corrupted file, a bad value found later) into
``error: <what> ... <what to do>`` on standard error and exit status 1, instead of a
traceback; an error of any other type is a bug and keeps its traceback. The scripts in
``benchmarks/`` and the skill trainers (:mod:`torchrl_causal.experts.skill_run`) take argparse
``--flags`` instead, through :class:`OneLineParser` and the bounded types of :func:`bounded`.
This module stands low in the package (it imports only :mod:`torchrl_causal.errors`) so that
every one of them can use it; :mod:`torchrl_causal.cli.arguments` is its old path.

Examples:
    >>> options = {"runs": Option(str), "episodes": Option(int, 1000, ge=1), "regime": Option(str, "deploy",
    ...            choices=("train", "deploy"))}
    >>> parse_arguments("demo", ["runs=r", "episodes=20"], options)
    {'runs': 'r', 'episodes': 20, 'regime': 'deploy'}
    >>> parse_arguments("demo", ["runs=r", "episodes=abc"], options)
    Traceback (most recent call last):
    ...
    SystemExit: error: episodes='abc' must be an integer
    >>> parse_arguments("demo", ["runs=r", "regime=foo"], options)
    Traceback (most recent call last):
    ...
    SystemExit: error: regime='foo' must be one of train, deploy
    >>> parse_arguments("demo", ["runs=r", "episodes=4", "episodes=8"], options)
    Traceback (most recent call last):
    ...
    SystemExit: error: episodes is given twice (episodes=4, then episodes=8): give it once
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, cast

from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from torchrl_causal.errors import InvalidTypeError

__all__ = [
    "HELP_FLAGS",
    "REQUIRED",
    "OneLineParser",
    "Option",
    "argv_or_sys",
    "bounded",
    "count",
    "help_text",
    "non_negative",
    "non_negative_number",
    "positive_number",
    "one_line_errors",
    "parse_arguments",
    "refuse_repeated_keys",
    "usage",
]

#: The default of an argument that must be given.
REQUIRED: Any = object()

#: What asks a command for its help instead of running it.
HELP_FLAGS = ("--help", "-h", "help")


@dataclass(frozen=True)
class Option:
    """One ``key=value`` argument.

    Args:
        kind: ``int``, ``float``, ``bool``, ``str`` or ``list`` (a list of ``item`` s).
        default: its value when not given; :data:`REQUIRED` when it must be given, ``None``
            for "not set" (the value is then ``None``).
        ge, le: inclusive bounds of a number (of every item of a list).
        choices: the allowed values.
        item: the kind of a list's items.
        placeholder: what the usage line shows for the value.
        help: what the option sets (one line of the command's ``--help``).
    """

    kind: type
    default: Any = REQUIRED
    ge: float | None = None
    le: float | None = None
    choices: tuple[Any, ...] = ()
    item: type = str
    placeholder: str = ""
    help: str = ""

    def shown(self, name: str) -> str:
        """The value the usage line shows: the default, or a placeholder."""
        if self.placeholder:
            return self.placeholder
        if self.default in (REQUIRED, None):
            return f"<{name}>"
        if isinstance(self.default, bool):
            return str(self.default).lower()
        if isinstance(self.default, list):
            return "[" + ",".join(map(str, self.default)) + "]"
        return str(self.default)

    def usage(self, name: str) -> str:
        return f"{name}={self.shown(name)}" if self.default is REQUIRED else f"[{name}={self.shown(name)}]"

    def accepts(self) -> str:
        """What values it takes, in words (``an integer >= 1``, ``one of train, deploy``)."""
        kind = _KIND_NAMES[self.kind] if self.kind is not list else f"a list of {_KIND_NAMES[self.item].split(' ', 1)[-1]}s"
        if self.choices:
            kind = f"one of {', '.join(map(str, self.choices))}"
        bounds = [f">= {self.ge:g}" if self.ge is not None else "", f"<= {self.le:g}" if self.le is not None else ""]
        return " ".join([kind, *filter(None, bounds)])


def usage(command: str, options: Mapping[str, Option]) -> str:
    """The usage line of ``python -m torchrl_causal.<command>``."""
    return f"usage: python -m torchrl_causal.{command} " + " ".join(option.usage(name) for name, option in options.items())


def _first_paragraph(doc: str) -> str:
    """A module docstring's first paragraph as plain text (one line, no reST markup)."""
    paragraph = doc.strip().split("\n\n")[0]
    return " ".join(paragraph.replace("``", "").replace(":func:", "").replace(":mod:", "").split())


def help_text(command: str, options: Mapping[str, Option], about: str = "", example: str = "") -> str:
    """The answer to ``python -m torchrl_causal.<command> --help``: the usage line, what the
    command does (``about``: its module docstring, of which the first paragraph is kept), each
    option with its default and the values it takes, and ``example``.

    Examples:
        >>> print(help_text("status", {"runs": Option(str, placeholder="<dir>", help="the folder of runs")},
        ...                 "Where the runs stand.", "python -m torchrl_causal.status runs=runs"))
        usage: python -m torchrl_causal.status runs=<dir>
        <BLANKLINE>
        Where the runs stand.
        <BLANKLINE>
        options (key=value; [...] ones are optional, shown with their default):
          runs=<dir>  (required) the folder of runs; a string
        <BLANKLINE>
        example: python -m torchrl_causal.status runs=runs
    """
    lines = [usage(command, options), ""]
    if about:
        lines += [_first_paragraph(about), ""]
    if options:
        width = max(len(f"{name}={option.shown(name)}") for name, option in options.items())
        lines.append("options (key=value; [...] ones are optional, shown with their default):")
        for name, option in options.items():
            described = "; ".join(filter(None, [option.help, option.accepts()]))
            required = "(required) " if option.default is REQUIRED else ""
            lines.append(f"  {f'{name}={option.shown(name)}':<{width}}  {required}{described}")
    else:
        lines.append("options: none")
    if example:
        lines += ["", f"example: {example}"]
    return "\n".join(lines)


_KIND_NAMES = {int: "an integer", float: "a number", bool: "true or false", str: "a string", list: "a list [a,b,...]"}


def _convert(name: str, raw: Any, kind: type) -> Any:
    text = f"{name}={raw!r}"
    if kind is bool:
        if isinstance(raw, bool):
            return raw
        raise SystemExit(f"error: {text} must be {_KIND_NAMES[bool]}")
    if kind is int:
        if isinstance(raw, int) and not isinstance(raw, bool):
            return raw
        raise SystemExit(f"error: {text} must be an integer")
    if kind is float:
        if isinstance(raw, (int, float)) and not isinstance(raw, bool) and math.isfinite(raw):
            return float(raw)
        raise SystemExit(f"error: {text} must be a finite number")
    if kind is str:
        if isinstance(raw, (str, int, float)) and not isinstance(raw, bool) and str(raw):
            return str(raw)
        raise SystemExit(f"error: {text} must be a non-empty string")
    raise InvalidTypeError(f"unsupported option kind {kind!r}")


def _check(name: str, value: Any, option: Option) -> None:
    if option.choices and value not in option.choices:
        raise SystemExit(f"error: {name}={value!r} must be one of {', '.join(map(str, option.choices))}")
    if option.ge is not None and value < option.ge:
        raise SystemExit(f"error: {name}={value!r} is out of range: it must be >= {option.ge:g}")
    if option.le is not None and value > option.le:
        raise SystemExit(f"error: {name}={value!r} is out of range: it must be <= {option.le:g}")


def refuse_repeated_keys(argv: Sequence[str]) -> None:
    """Refuses a ``key=value`` argument whose key was given before (Hydra's ``+``/``++``/``~``
    prefixes aside): OmegaConf and Hydra would keep the last value without a word, so
    ``episodes=4 episodes=8`` would run what the user may not have meant.

    Raises:
        SystemExit: one line naming the key and both arguments.

    Examples:
        >>> refuse_repeated_keys(["episodes=4", "seed=1", "-m"])
        >>> refuse_repeated_keys(["episodes=4", "episodes=8"])
        Traceback (most recent call last):
        ...
        SystemExit: error: episodes is given twice (episodes=4, then episodes=8): give it once
    """
    seen: dict[str, str] = {}
    for argument in argv:
        if "=" not in argument or argument.startswith("-"):
            continue
        key = argument.split("=", 1)[0].lstrip("+~")
        if key in seen:
            raise SystemExit(f"error: {key} is given twice ({seen[key]}, then {argument}): give it once")
        seen[key] = argument


def parse_arguments(
    command: str, argv: Sequence[str], options: Mapping[str, Option], *, about: str = "", example: str = ""
) -> dict[str, Any]:
    """The typed value of every option (its default when not given).

    Args:
        command: the command's name (``python -m torchrl_causal.<command>``).
        argv: its ``key=value`` arguments.
        options: what it takes.
        about, example: what ``--help`` says the command does, and one command line
            (see :func:`help_text`).

    Raises:
        SystemExit: status 0 after printing the help, for ``--help``, ``-h`` or ``help``;
            with the usage line for an unknown or missing argument or a malformed one;
            with one line naming the argument for a value of the wrong type or out of
            range, or for a key given twice (:func:`refuse_repeated_keys`).
    """
    if any(argument in HELP_FLAGS for argument in argv):
        print(help_text(command, options, about, example))
        raise SystemExit(0)
    line = usage(command, options)
    refuse_repeated_keys(argv)
    try:
        # from_cli builds a DictConfig, whose container is a dict keyed by the argument names.
        args = cast(dict[str, Any], OmegaConf.to_container(OmegaConf.from_cli(list(argv))))
    except (OmegaConfBaseException, ValueError) as error:
        raise SystemExit(f"error: cannot parse the arguments ({str(error).splitlines()[0]}); {line}") from None
    unknown = sorted(set(args) - set(options))
    missing = [name for name, option in options.items() if option.default is REQUIRED and name not in args]
    if unknown or missing:
        named = [f"unknown argument(s) {unknown}"] if unknown else []
        named += [f"missing {', '.join(missing)}"] if missing else []
        raise SystemExit(f"{line}\n({'; '.join(named)})")
    values: dict[str, Any] = {}
    for name, option in options.items():
        if name not in args or args[name] is None:
            values[name] = None if name not in args and option.default is REQUIRED else option.default
            if name in args and option.default is REQUIRED:
                raise SystemExit(f"error: {name} must be given a value; {line}")
            continue
        raw = args[name]
        if option.kind is list:
            items = raw if isinstance(raw, list) else [raw]
            if not items:
                raise SystemExit(f"error: {name}=[] must name at least one value")
            values[name] = [_convert(name, item, option.item) for item in items]
            for item in values[name]:
                _check(name, item, option)
        else:
            values[name] = _convert(name, raw, option.kind)
            _check(name, values[name], option)
    return values


def _describe(error: BaseException) -> str:
    if isinstance(error, OSError) and error.filename is not None and error.strerror:
        return f"{error.filename}: {error.strerror}"
    if isinstance(error, MemoryError):
        return "out of memory" + (f": {error}" if str(error) else "") + "; lower the sizes of the command"
    return str(error) or type(error).__name__


@contextmanager
def one_line_errors(*user_errors: type[BaseException]) -> Iterator[None]:
    """Turns the faults a user causes into one line on standard error and exit status 1.

    Caught: missing or unreadable files (``OSError``), bad values (``ValueError``, which
    covers JSON that does not parse), memory exhaustion, OmegaConf's errors on stored configs, and ``user_errors`` (a
    command's own, e.g. :class:`~torchrl_causal.experiment.run_directory.CheckpointError`).
    Anything else propagates with its traceback: it is a bug to report.

    Examples:
        >>> with one_line_errors():
        ...     open("/nonexistent/file")
        Traceback (most recent call last):
        ...
        SystemExit: error: /nonexistent/file: No such file or directory
    """
    caught: tuple[type[BaseException], ...] = (OSError, ValueError, MemoryError, OmegaConfBaseException, *user_errors)
    try:
        yield
    except caught as error:
        message = " ".join(_describe(error).split())  # one line, whatever the error's own layout
        raise SystemExit(f"error: {message}") from None


def argv_or_sys(argv: Sequence[str] | None) -> list[str]:
    """``argv``, or the process's own arguments when it is ``None``."""
    return list(sys.argv[1:] if argv is None else argv)


# ---------------------------------------------------------------------- the benchmarks' argparse flags


class OneLineParser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose refusals are one line (``error: ...``, exit
    status 2), as the package's commands answer: what the scripts in ``benchmarks/`` and the
    skill trainers parse their ``--flags`` with, typed by :func:`bounded` (:data:`count`, :data:`non_negative`...).

    Examples:
        >>> parser = OneLineParser(prog="bench")
        >>> _ = parser.add_argument("--steps", type=count, default=10)
        >>> parser.parse_args(["--steps", "3"]).steps
        3
        >>> parser.parse_args(["--steps", "-5"])
        Traceback (most recent call last):
        ...
        SystemExit: 2
    """

    def error(self, message: str) -> None:  # type: ignore[override]  # argparse's own is NoReturn too
        self.exit(2, f"error: {message} (python {self.prog} --help lists the options)\n")


def bounded(kind: type, *, ge: float | None = None, gt: float | None = None) -> Callable[[str], Any]:
    """An argparse ``type=`` that reads ``kind`` (``int`` or a finite ``float``) and refuses a
    value below ``ge`` or not above ``gt``, naming it.

    Examples:
        >>> count("4"), non_negative("0"), positive_number("0.5")
        (4, 0, 0.5)
        >>> count("-5")
        Traceback (most recent call last):
        ...
        argparse.ArgumentTypeError: -5 must be an integer >= 1
        >>> positive_number("nan")
        Traceback (most recent call last):
        ...
        argparse.ArgumentTypeError: nan must be a finite number > 0
    """
    name = "an integer" if kind is int else "a finite number"
    bound = f" >= {ge:g}" if ge is not None else f" > {gt:g}" if gt is not None else ""

    def read(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text} must be {name}{bound}") from None
        if (kind is float and not math.isfinite(value)) or (ge is not None and value < ge) or (gt is not None and value <= gt):
            raise argparse.ArgumentTypeError(f"{text} must be {name}{bound}")
        return value

    read.__name__ = f"{kind.__name__}{bound.replace(' ', '')}"  # what argparse names in its messages
    return read


#: A count of things (steps, rounds, episodes, threads): an integer >= 1.
count = bounded(int, ge=1)
#: A seed, a window size, an optional number of things: an integer >= 0.
non_negative = bounded(int, ge=0)
#: A rate, a length, a radius: a finite number > 0.
positive_number = bounded(float, gt=0)
#: A clearance, a height: a finite number >= 0.
non_negative_number = bounded(float, ge=0)
