"""The one fingerprint helper: keys written by earlier versions must come out the same.

Stores, caches and resumable runs key entries by these strings; a changed key silently turns
every saved result into a miss. The expected values below were computed with the formulas the
call sites used before they shared :mod:`fsdvs_hw.fingerprints` (``hashlib.sha1`` over
``json.dumps(..., sort_keys=True, default=str)`` or over the text), so a change to the helper's
encoding fails here.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.fingerprints import fingerprint, text_fingerprint
from fsdvs_hw.paths import safe_name


def _old_json_key(value: object, length: int | None) -> str:
    return hashlib.sha1(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()[:length]


@pytest.mark.parametrize("length", [None, 10, 16, 20])
def test_fingerprint_equals_the_formula_the_stores_were_written_with(length: int | None) -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        value = {
            "taps": rng.normal(size=(3, 3)).round(15).tolist(),
            "task": str(rng.choice(["flow", "segmentation", "classification"])),
            "threshold": float(rng.uniform(0.05, 0.5)),
            "path": Path("/tmp") / f"ck{rng.integers(99)}.pt",  # not JSON: written as str()
            "n_test": None,
        }
        assert fingerprint(value, length=length) == _old_json_key(value, length)


def test_key_order_does_not_change_the_fingerprint() -> None:
    assert fingerprint({"a": 1, "b": [2, 3]}) == fingerprint({"b": [2, 3], "a": 1})
    assert fingerprint({"a": 1, "b": [2, 3]}) != fingerprint({"a": 1, "b": [3, 2]})


def test_pinned_values() -> None:
    # SHA-1 test vector (FIPS 180-2, "abc") and a store-style key computed once, by hand.
    assert text_fingerprint("abc") == "a9993e364706816aba3e25717850c26c9cd0d89d"
    assert text_fingerprint(b"abc", length=10) == "a9993e3647"
    assert fingerprint({"threshold": 0.2, "task": "flow"}, length=16) == "448a1b4601ed82f9"


def test_safe_name_suffix_is_unchanged_for_undecodable_names() -> None:
    name = "bad\udcffname/../x"  # a lone surrogate, as os.fsdecode gives for undecodable bytes
    old = hashlib.sha1(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    assert safe_name(name).endswith("-" + old)


@pytest.mark.parametrize("length", [0, 41, -1])
def test_length_out_of_range_is_refused(length: int) -> None:
    with pytest.raises(ValueError, match="allowed: 1 to 40"):
        text_fingerprint("x", length=length)
