"""Strings and numbers from the wire stay short in errors and the status (issue 16).

A 10 KB encoding name was copied whole into the log and ``/diagnostics`` ``last error``; a
joint velocity of 1e308 was shown with 309 digits. Here the session and the status, without
ROS: the node's and the replay's texts come from them (the DDS test is in
test/ros/test_node_hardening.py).
"""

from __future__ import annotations

from types import SimpleNamespace

from domplane_ros.core.image import message_to_gray
from domplane_ros.errors import clip_text, ImageDecodeError, wire_repr
from domplane_ros.stream.session import LAST_ERROR_CHARS, StreamSession
from domplane_ros.stream.status import format_number, plane_status
import pytest
from test_session import _feed, _msg, T0


def test_clip_text_and_wire_repr_say_how_long_the_string_was():
    assert clip_text('abc', 5) == 'abc'
    assert clip_text('x' * 10, 4) == 'xxxx... (10 characters)'
    assert wire_repr('mono8') == "'mono8'"
    assert wire_repr('y' * 10240, 3) == "'yyy'... (10240 characters)"
    assert wire_repr(12345, 3) == '123... (5 characters)'


@pytest.mark.parametrize('field, value, needle', [
    ('encoding', 'e' * 10240, "unsupported encoding 'eeee"),
    ('height', 'h' * 10240, "image field 'height' must be an integer, got 'hhhh"),
])
def test_decode_errors_clip_the_message_field(field, value, needle):
    msg = _msg(T0)
    setattr(msg, field, value)
    with pytest.raises(ImageDecodeError) as info:
        message_to_gray(msg)
    text = str(info.value)
    assert needle in text and '... (10240 characters)' in text and len(text) < 250, text


def test_compressed_format_is_clipped():
    msg = SimpleNamespace(header=_msg(T0).header, format='f' * 5000, data=b'\x00' * 10)
    with pytest.raises(ImageDecodeError, match=r"unsupported compressed format 'f+'\.\.\. "
                                               r'\(5000 characters\)'):
        message_to_gray(msg)


def test_session_status_holds_a_clipped_last_error():
    session = StreamSession()
    assert _feed(session, 0, 0.0, encoding='q' * 10240) == [None]
    assert '(10240 characters)' in session.last_error
    assert len(session.last_error) <= LAST_ERROR_CHARS + 30
    level, message, values = session.status(1.0)
    assert len(dict(values)['last error']) <= LAST_ERROR_CHARS + 30
    assert len(message) < 400
    session.note_internal_error(RuntimeError('r' * 100_000))
    assert len(session.last_error) <= LAST_ERROR_CHARS + 30


def test_status_numbers_have_a_sane_precision():
    assert format_number(2.5) == '2.50' and format_number(0.2, 3) == '0.200'
    assert format_number(1e308) == '1.000e+308' and format_number(-3e9, 1) == '-3.000e+09'
    assert format_number(float('nan')) == 'nan' and format_number(float('inf')) == 'inf'
    _, message, values = plane_status(
        rate=1e308, latencies_ms=[1e300], pairs=1, processed=1, dropped_busy=0,
        dropped_sync=0, decode_errors=0, lock_state='searching', reinitialisations=0,
        consecutive_failures=0, last_result=None, last_error='', joint_speed=1e308,
        cameras=[('/left/image_raw', 1, 1e200, 3.2e9)], silence_s=1.0)
    values = dict(values)
    assert values['head joint speed [rad/s]'] == '1.000e+308'
    assert values['input rate [pairs/s]'] == '1.000e+308'
    assert values['processing latency median [ms]'] == '1.000e+300'
    assert values['/left/image_raw last image age [s]'] == '3.200e+09'
    assert message == 'no images on /left/image_raw for 3.200e+09 s'
    assert max(len(v) for v in values.values()) < 40
