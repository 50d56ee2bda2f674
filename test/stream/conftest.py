"""Fixtures of the stream tests."""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.stream import trust as trust_module
import pytest


@pytest.fixture
def counted_score(monkeypatch):
    """Score pixels counted, not weighted by contrast, as the scenes of its tests were chosen.

    Their checks (swap, doubt, rescue, bottom, beyond) were measured on planes the counted
    score verified; weighted by contrast (core/verification.py, step 5; the default since
    the twelfth round) those planes are refused earlier or the truth wins outright, and the
    check would go untested.
    """
    original = trust_module.TrustGate.config

    def counted(self, width):
        return replace(original(self, width), weight_by_contrast=False)

    monkeypatch.setattr(trust_module.TrustGate, 'config', counted)
