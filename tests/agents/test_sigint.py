"""A Ctrl-C inside ``sigint_deferred`` waits for the block: updates and files stay whole."""

import os
import signal
import time

import pytest

from agents.sigint import sigint_deferred


def _ctrl_c() -> None:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)  # the handler runs between bytecodes, so give it some


def test_ctrl_c_in_the_block_is_raised_once_the_block_has_run():
    ran = []
    with pytest.raises(KeyboardInterrupt), sigint_deferred():
        _ctrl_c()
        ran.append("rest of the block")
    assert ran == ["rest of the block"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_nested_blocks_hand_a_ctrl_c_to_the_outer_one():
    ran = []
    with pytest.raises(KeyboardInterrupt), sigint_deferred():
        with sigint_deferred():
            _ctrl_c()
        ran.append("rest of the outer block")
    assert ran == ["rest of the outer block"]
