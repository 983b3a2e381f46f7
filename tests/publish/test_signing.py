"""Goal messages a client can trust (issue 16, "Results ... trusted only from the daemon"): the key
of publish/signing.py, and the daemon signing every goal's feedback and result with it.

Before, a goal's feedback and result went out bare: any session could publish a result on the goal's
key and a client took it (the issue's probe: a forged ``succeeded`` returned 2.5 s early). Now the
accepting reply gives a key, and every message of the goal carries its signature as the attachment.
"""

from __future__ import annotations

import hashlib
import hmac
import json
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Received
from urdaemon.publish import signing

pytestmark = pytest.mark.timeout(120)

TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]


# ---- publish/signing.py --------------------------------------------------------------------------------


def test_a_key_is_fresh_hex_of_its_length() -> None:
    keys = {signing.new_key() for _ in range(100)}
    assert len(keys) == 100
    for key in keys:
        assert len(key) == 2 * signing.KEY_BYTES
        assert bytes.fromhex(key)


FEEDBACK = "cell/alice/goal/alice-1a2b-1/feedback"
RESULT = "cell/alice/goal/alice-1a2b-1/result"


@given(st.binary(max_size=4096))
def test_a_signature_verifies_under_its_key_only(payload: bytes) -> None:
    key, other = signing.new_key(), signing.new_key()
    signature = signing.sign(key, RESULT, payload)
    assert signature == signing.sign(key, RESULT, payload), "deterministic"
    assert len(signature) == 64
    assert signature.isascii()
    assert signing.verify(key, RESULT, payload, signature)
    assert not signing.verify(other, RESULT, payload, signature)
    assert not signing.verify(key, RESULT, payload + b"x", signature)
    assert not signing.verify(key, RESULT, payload, None)
    assert not signing.verify(key, RESULT, payload, b"")
    assert not signing.verify(key, RESULT, payload, signature[:-1])


@given(st.binary(max_size=1024))
def test_a_feedback_signature_does_not_verify_on_the_result_key(payload: bytes) -> None:
    """H3 (review 16, repro test_r_replay): a session that hears a goal's signed feedback re-published
    it, attachment and all, on the goal's result key, and the client returned it as the result while
    the robot still moved. The signature now covers the key the message was published on."""
    key = signing.new_key()
    feedback = signing.sign(key, FEEDBACK, payload)
    assert signing.verify(key, FEEDBACK, payload, feedback)
    assert not signing.verify(key, RESULT, payload, feedback)
    assert feedback != signing.sign(key, RESULT, payload)


def test_the_key_and_payload_cannot_trade_bytes() -> None:
    """The NUL between key and payload: moving bytes from one to the other changes the signature."""
    key = signing.new_key()
    assert signing.sign(key, "a/b", b"c") != signing.sign(key, "a/bc", b"")
    assert signing.sign(key, "a/b", b"/c") != signing.sign(key, "a/b/c", b"")


def test_no_signature_verifies_under_a_key_that_is_not_a_goal_key() -> None:
    """An empty or malformed key (a reply that gave none) never verifies anything, even what was
    signed with it."""
    for bad in ("", "00", "Jefe", "0" * 63, "G" * 64, "A" * 64, " " + "0" * 63):
        assert not signing.is_key(bad)
        assert not signing.verify(bad, RESULT, b"{}", b"0" * 64)
    assert not signing.verify("", RESULT, b"{}", signing.sign("", RESULT, b"{}"))
    assert signing.is_key(signing.new_key())


def test_a_known_signature() -> None:
    """HMAC-SHA256 with RFC 4231 test case 2's key ("Jefe") over ``key_expr + NUL + payload``; the
    expected value was computed outside Python (``printf 'what do ya\\0want for nothing?' | openssl
    dgst -sha256 -hmac Jefe``): what any client can check with its own HMAC library."""
    key = b"Jefe".hex()
    expected = b"42b4c08329a84bc32d09fd144b387c697f41fc088aa400bb44dc6cc936f6c849"
    assert signing.sign(key, "what do ya", b"want for nothing?") == expected
    # and the RFC's own vector, for the HMAC itself (no NUL: not a message the daemon signs)
    rfc = "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
    assert hmac.new(b"Jefe", b"what do ya want for nothing?", hashlib.sha256).hexdigest() == rfc


# ---- the daemon's goals --------------------------------------------------------------------------------


def _messages(received: list[Received], goal_id: str, kind: str) -> list[Received]:
    return [r for r in received if r.key.endswith(f"/goal/{goal_id}/{kind}")]


async def test_a_goals_reply_carries_a_key_and_every_message_of_it_verifies() -> None:
    async with running_daemon(TWO_MOCKS) as (_, client):
        alice = await client.robot("alice")
        token = await alice.ensure_lease()
        sub = client.subscribe(alice.keys.goal_messages)
        reply = await client.request(
            alice.keys.goal_move, {"positions": TARGET, "duration": 1.0}, attachment=token.encode() or None
        )
        assert reply["accepted"] is True, reply
        key = reply["result_key"]
        assert len(key) == 2 * signing.KEY_BYTES
        goal_id = reply["goal_id"]
        received: list[Received] = []
        for _ in range(1000):  # feedback at 10 Hz for 1 s, then the result
            received.append(await sub.get_sample(timeout=10.0))
            if received[-1].key.endswith("/result"):
                break
        feedback = _messages(received, goal_id, "feedback")
        results = _messages(received, goal_id, "result")
        assert feedback, "feedback was published"
        assert len(results) == 1
        for message in feedback + results:  # each verifies on the key it arrived on, only there
            assert signing.verify(key, message.key, message.payload, message.attachment), message
        result_key = alice.keys.goal_result(goal_id)
        assert results[0].key == result_key
        for message in feedback:  # re-published on the result key, a feedback is not the daemon's
            assert not signing.verify(key, result_key, message.payload, message.attachment), message
        assert json.loads(results[0].payload)["status"] == "succeeded"
        # a late query for the result is answered signed too
        late = await client.query_replies(alice.keys.goal_result(goal_id))
        assert len(late) == 1
        assert late[0].payload == results[0].payload
        assert late[0].key == result_key
        assert signing.verify(key, late[0].key, late[0].payload, late[0].attachment)
        # another goal has another key
        again = await client.request(
            alice.keys.goal_move, {"positions": TARGET, "duration": 1.0}, attachment=token.encode() or None
        )
        assert again["result_key"] != key
        await alice.cancel(again["goal_id"])


async def test_the_client_returns_the_signed_result_not_a_forged_one() -> None:
    async with running_daemon(TWO_MOCKS) as (_, client):
        bob = await client.robot("bob")
        goal = await bob.move(TARGET, duration=30.0)
        forged: dict[str, Any] = {"v": 1, "goal_id": goal.goal_id, "robot": "bob", "status": "succeeded"}
        forged |= {"reason": "forged", "final_positions": TARGET, "final_error": [0.0] * 6, "duration": 0.1}
        client.session.put(bob.keys.goal_result(goal.goal_id), json.dumps(forged).encode())
        client.session.put(
            bob.keys.goal_result(goal.goal_id), json.dumps(forged).encode(), attachment=b"0" * 64
        )
        await bob.cancel(goal.goal_id)
        result = await goal.result(timeout=20.0)
        assert result["status"] == "canceled", result
