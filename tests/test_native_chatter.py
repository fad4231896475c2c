"""MediaPipe's native info and warning lines are kept off stderr; everything else gets through."""

import os
import tempfile
import threading
import time

import numpy as np

from physpose import native_chatter
from physpose.observe import ObserveConfig, PoseDetector

CHATTER = [
    b"INFO: Created TensorFlow Lite XNNPACK delegate for CPU.",
    b"WARNING: All log messages before absl::InitializeLog() is called are written to STDERR",
    b"W0000 00:00:1796184456.900044    5344 inference_feedback_manager.cc:114] Feedback "
    b"manager requires a model with a single signature inference.",
    b"W1202 04:12:01.123456   77 landmark_projection_calculator.cc:186] Using NORM_RECT",
    b"I0000 00:00:1796184456.9 12 gl_context.cc:369] GL version: 3.2",
]
KEPT = [
    b"E0000 00:00:1796184456.900044    5344 calculator_graph.cc:887] a real failure",
    b"observe clip.mp4:  50%|#####     | 1/2",
    b"INFO: something physpose does not know",
    b"Warning: a Python warning",
]


def test_chatter_lines_are_told_from_the_rest():
    assert all(native_chatter.is_chatter(line) for line in CHATTER)
    assert not any(native_chatter.is_chatter(line) for line in KEPT)


def _forwarded(data: bytes) -> bytes:
    source, into = os.pipe()
    with tempfile.TemporaryFile() as sink:
        os.write(into, data)
        os.close(into)
        native_chatter.forward(source, sink.fileno())
        os.close(source)
        sink.seek(0)
        return sink.read()


def test_forward_drops_chatter_lines_and_keeps_the_rest_in_order():
    mixed = [CHATTER[0], KEPT[0], CHATTER[2], KEPT[1], CHATTER[1], KEPT[2]]
    assert _forwarded(b"\n".join(mixed) + b"\n") == b"".join(
        line + b"\n" for line in (KEPT[0], KEPT[1], KEPT[2]))
    # An unfinished last line is kept unless it is chatter.
    assert _forwarded(b"a\nWARNING: unfinished") == b"a\nWARNING: unfinished"
    assert _forwarded(b"a\n" + CHATTER[2]) == b"a\n"


def test_a_progress_bar_is_forwarded_before_its_line_ends():
    source, into = os.pipe()
    with tempfile.TemporaryFile() as sink:
        thread = threading.Thread(target=native_chatter.forward, args=(source, sink.fileno()))
        thread.start()
        os.write(into, b"\rbar 1/3")
        deadline = time.monotonic() + 10
        while os.fstat(sink.fileno()).st_size == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        arrived = os.fstat(sink.fileno()).st_size
        os.close(into)
        thread.join()
        os.close(source)
    assert arrived == len(b"\rbar 1/3")


def test_filtered_keeps_native_chatter_off_stderr(capfd):
    with native_chatter.filtered():
        os.write(2, CHATTER[2] + b"\n" + KEPT[0] + b"\n" + CHATTER[0] + b"\n")
    os.write(2, b"after\n")
    assert capfd.readouterr().err == KEPT[0].decode() + "\nafter\n"


def test_pose_detector_starts_without_native_chatter(capfd):
    with PoseDetector(ObserveConfig()) as detector:
        detector.detect(np.zeros((240, 320, 3), np.uint8))
    err = capfd.readouterr().err
    assert "XNNPACK" not in err and "inference_feedback_manager" not in err, err
