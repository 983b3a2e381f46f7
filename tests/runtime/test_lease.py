"""The command lease book (runtime/lease.py), pure: grants, refusals, take-over, release, the holder
gone, and the view Zenoh's threads check."""

from __future__ import annotations

import hashlib
import json
import re

import pytest

from urdaemon.errors import MessageError
from urdaemon.model import fingerprint
from urdaemon.publish.lease_request import LeaseRequest, parse_request
from urdaemon.runtime.lease import LeaseBook

KEY = "cell/alice/lease"
NOW = 1_800_000_000.0
S1 = "a" * 16 + "1"
S2 = "b" * 16 + "2"
"""Session ids: secrets of 16 to 64 characters."""


def acquire(session: str, holder: str, *, force: bool = False, reason: str = "") -> LeaseRequest:
    return LeaseRequest("acquire", session, holder, force, reason)


def test_a_grant_is_a_fresh_secret_token_and_acquiring_again_returns_the_same() -> None:
    book = LeaseBook("alice", KEY)
    first = book.acquire(acquire(S1, "mover (pid 1)"), NOW)
    token = first.reply["token"]
    assert re.fullmatch(r"[0-9a-f]{32}", token)
    assert first.reply["lease"] == {"holder": "mover (pid 1)", "fingerprint": fingerprint(S1), "since": NOW}
    assert first.event == {
        "kind": "lease",
        "action": "acquired",
        "holder": "mover (pid 1)",
        "fingerprint": fingerprint(S1),
    }
    assert first.stop is None
    again = book.acquire(acquire(S1, "mover (pid 1)"), NOW + 5)
    assert again.reply["token"] == token
    assert again.event is None  # nothing changed
    other = LeaseBook("alice", KEY).acquire(acquire(S1, "x"), NOW)
    assert other.reply["token"] != token


def test_only_the_holders_token_passes_the_view_and_every_refusal_names_the_holder() -> None:
    book = LeaseBook("alice", KEY)
    free = book.current.refusal(None)
    assert free == (
        "lease: robot 'alice' needs its command lease for this (nobody holds it): a client acquires it "
        "by itself (`urdaemon move`, `RobotClient.ensure_lease()`); stopping needs none "
        "(`urdaemon stop alice`)"
    )
    assert KEY not in free, "the way out is a command, not a key"
    token = book.acquire(acquire(S1, "mover"), NOW).reply["token"].encode()
    assert book.current.refusal(token) is None
    assert book.refusal(token) is None
    for wrong in (None, b"", token[:-1], b"0" * 32, token + b"0"):
        reason = book.current.refusal(wrong)
        assert reason is not None
        assert reason.startswith("lease: robot 'alice' is held by mover since 2027-01-15T08:00:00+00:00;")
        assert "`urdaemon stop alice`" in reason, "the CLI's ways out, not a key"
        assert "`urdaemon lease alice --take-over REASON`" in reason
        assert KEY not in reason


def test_another_session_is_refused_unless_it_forces_with_a_reason() -> None:
    book = LeaseBook("alice", KEY)
    old = book.acquire(acquire(S1, "first"), NOW).reply["token"].encode()
    refused = book.acquire(acquire(S2, "second"), NOW + 1)
    assert refused.reply["ok"] is False
    assert "held by first" in refused.reply["reason"]
    assert "`urdaemon lease alice --take-over REASON`" in refused.reply["reason"]
    assert refused.reply["lease"]["fingerprint"] == fingerprint(S1)
    assert refused.stop is None
    assert refused.event is None
    taken = book.acquire(acquire(S2, "second", force=True, reason="first is stuck"), NOW + 2)
    assert taken.reply["ok"] is True
    assert taken.stop is not None
    assert "first is stuck" in taken.stop
    assert taken.warning is not None
    assert "first is stuck" in taken.warning
    assert taken.event == {
        "kind": "lease",
        "action": "taken_over",
        "holder": "second",
        "fingerprint": fingerprint(S2),
        "previous": {"holder": "first", "fingerprint": fingerprint(S1), "since": NOW},
        "reason": "first is stuck",
    }
    assert book.current.refusal(old) is not None
    assert book.current.refusal(taken.reply["token"].encode()) is None


def test_release_needs_the_holders_token_and_stops_the_robot() -> None:
    book = LeaseBook("alice", KEY)
    assert book.release(None).reply["ok"] is False  # nobody holds it
    token = book.acquire(acquire(S1, "first"), NOW).reply["token"].encode()
    for wrong in (None, b"f" * 32):
        outcome = book.release(wrong)
        assert outcome.reply["ok"] is False
        assert outcome.reply["reason"].startswith("lease: robot 'alice' is held by first")
        assert book.lease is not None
    released = book.release(token)
    assert released.reply == {"ok": True}
    assert released.stop is not None
    assert released.event is not None
    assert released.event["action"] == "released"
    assert book.lease is None
    assert book.current.refusal(token) is not None


def test_the_holder_gone_ends_the_lease_with_a_reason_naming_it() -> None:
    book = LeaseBook("alice", KEY)
    book.acquire(acquire(S1, "mover"), NOW)
    assert book.gone(S2) is None  # not the holder
    outcome = book.gone(S1)
    assert outcome is not None
    assert outcome.stop == "lease holder mover is gone"
    assert outcome.event == {
        "kind": "lease",
        "action": "lost",
        "holder": "mover",
        "fingerprint": fingerprint(S1),
        "reason": "lease holder mover is gone",
    }
    assert book.lease is None
    assert book.gone(S1) is None


def test_unenforced_nothing_is_checked_and_nothing_is_stopped() -> None:
    book = LeaseBook("alice", KEY)
    book.set_enforced(False)
    assert book.current.refusal(None) is None
    book.acquire(acquire(S1, "first"), NOW)
    assert book.current.refusal(b"nonsense") is None
    passed = book.acquire(acquire(S2, "second"), NOW + 1)  # no force needed: nothing is checked
    assert passed.reply["ok"] is True
    assert passed.stop is None
    gone = book.gone(S2)
    assert gone is not None
    assert gone.stop is None


@pytest.mark.parametrize(
    ("body", "named"),
    [
        ({"action": "grab"}, "'action'"),
        ({}, "'action'"),
        ({"action": "acquire", "holder": "x"}, "'session'"),
        ({"action": "acquire", "session": "a/b", "holder": "x"}, "'session'"),
        ({"action": "acquire", "session": "s" * 65, "holder": "x"}, "'session'"),
        ({"action": "acquire", "session": "s" * 15, "holder": "x"}, "'session'"),
        ({"action": "acquire", "session": S1, "holder": ""}, "'holder'"),
        ({"action": "acquire", "session": S1, "holder": "x" * 121}, "'holder'"),
        ({"action": "acquire", "session": S1, "holder": "a\nb"}, "'holder'"),
        ({"action": "acquire", "session": S1, "holder": "x", "force": True}, "'reason'"),
        ({"action": "acquire", "session": S1, "holder": "x", "force": True, "reason": " "}, "'reason'"),
        ({"action": "acquire", "session": S1, "holder": "x", "force": 1}, "'force'"),
        ({"action": "show", "extra": 1}, "extra"),
    ],
)
def test_bad_requests_are_refused_naming_what_is_wrong(body: dict[str, object], named: str) -> None:
    with pytest.raises(MessageError, match=re.escape(named)):
        parse_request(json.dumps(body).encode())


def test_good_requests_parse() -> None:
    assert parse_request(b'{"action": "show"}') == LeaseRequest("show")
    request = parse_request(
        json.dumps(
            {
                "v": 1,
                "action": "acquire",
                "session": "ab-9_Z" * 3,
                "holder": "me",
                "force": True,
                "reason": "r",
            }
        ).encode()
    )
    assert request == LeaseRequest("acquire", "ab-9_Z" * 3, "me", True, "r")


def test_the_book_shows_a_fingerprint_and_never_the_session_id() -> None:
    """Review 16 H1: whoever names a lease's session id gets its token, so no reply, event, stop
    reason or warning of the book shows it; they show ``fingerprint`` (16 hex characters of its
    SHA-256)."""
    assert fingerprint(S1) == hashlib.sha256(S1.encode()).hexdigest()[:16]
    assert re.fullmatch(r"[0-9a-f]{16}", fingerprint(S2))
    book = LeaseBook("alice", KEY)
    outcomes = [
        book.acquire(acquire(S1, "first"), NOW),
        book.acquire(acquire(S2, "second"), NOW + 1),
        book.acquire(acquire(S2, "second", force=True, reason="stuck"), NOW + 2),
    ]
    token = outcomes[-1].reply["token"].encode()
    outcomes += [book.release(b"0" * 32), book.release(token), book.acquire(acquire(S1, "first"), NOW + 3)]
    gone = book.gone(S1)
    assert gone is not None
    shown = json.dumps(
        [[o.reply, o.event, o.stop, o.warning] for o in [*outcomes, gone]]
        + [book.show(), book.current.refusal_text]
    )
    assert S1 not in shown
    assert S2 not in shown
    assert fingerprint(S1) in shown
    assert fingerprint(S2) in shown
