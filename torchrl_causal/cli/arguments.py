"""The command lines' argument parsing, at its old path: it lives in :mod:`torchrl_causal.arguments`
(below :mod:`torchrl_causal.experts`, whose skill trainers parse their ``--flags`` with it too)."""

from torchrl_causal.arguments import (
    REQUIRED,
    OneLineParser,
    Option,
    argv_or_sys,
    bounded,
    count,
    non_negative,
    non_negative_number,
    one_line_errors,
    parse_arguments,
    positive_number,
    refuse_repeated_keys,
    usage,
)

__all__ = [
    "REQUIRED",
    "OneLineParser",
    "Option",
    "argv_or_sys",
    "bounded",
    "count",
    "non_negative",
    "non_negative_number",
    "one_line_errors",
    "parse_arguments",
    "positive_number",
    "refuse_repeated_keys",
    "usage",
]
