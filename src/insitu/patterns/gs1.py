"""GS1 element strings: the GTIN of AI (01) must carry its own check digit (a wrong one is a
typo a scanner at the customer's would refuse)."""

from __future__ import annotations

import re

from insitu.errors import FormatError

_GTIN = re.compile(r"\(01\)(\d*)")


def gtin_check_digit(digits: str) -> int:
    """GS1 mod-10 check digit of the 13 (or any number of) data digits before it."""
    total = sum(int(d) * (3 if i % 2 == 0 else 1) for i, d in enumerate(reversed(digits)))
    return (10 - total % 10) % 10


def check_gtin(data: str, where: str) -> None:
    """A GS1 element string's GTIN, AI (01): 14 digits whose last is their check digit;
    FormatError naming it otherwise. Data without (01) passes."""
    for m in _GTIN.finditer(data):
        gtin = m[1][:14]
        if len(gtin) != 14:
            raise FormatError(f"{where}: GTIN (01){gtin}: expected 14 digits, got {len(gtin)}")
        want = gtin_check_digit(gtin[:13])
        if int(gtin[13]) != want:
            raise FormatError(f"{where}: GTIN (01){gtin}: wrong check digit {gtin[13]} "
                              f"(expected {want})")
