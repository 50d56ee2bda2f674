"""The helper every tool shares: one core, the prior around a set-up, messages, progress."""

from __future__ import annotations

import os

import cv2
from domplane_ros.core.image import message_to_gray
from domplane_ros.tools import common
import numpy as np
import pytest


def test_one_core_pins_opencv_and_blas_and_restores_them():
    cv2.setNumThreads(2)
    blas = common._openblas_thread_calls()
    before = [get() for get, _ in blas]
    with common.one_core():
        assert cv2.getNumThreads() == 1
        assert all(get() == 1 for get, _ in blas)
    assert cv2.getNumThreads() == 2
    assert [get() for get, _ in blas] == before


@pytest.mark.skipif(not os.path.exists('/proc/self/maps'), reason='Linux only')
def test_numpy_openblas_is_found():
    assert common._openblas_thread_calls(), 'numpy wheels bundle OpenBLAS'


def test_mono8_message_decodes_to_the_image():
    gray = np.arange(12, dtype=np.uint8).reshape(3, 4)
    msg = common.mono8_message(gray, 1_500_000_000)
    np.testing.assert_array_equal(message_to_gray(msg), gray)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 500_000_000)


def test_progress_keeps_the_items_and_the_machine_has_a_name():
    assert list(common.progress(range(3), 'test', disable=True)) == [0, 1, 2]
    assert '1 used' in common.machine_name()
