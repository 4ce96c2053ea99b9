"""/diagnostics by diagnostic_updater's conventions, and the start handshake's rules.

The rate, latency and window checks are plain functions (nodes/health.py); the handshake's
decision runs on a real rclpy node in this process (nodes/handshake.py).
"""

from __future__ import annotations

import math
import time

import pytest

from zeus_ros.nodes.health import WindowCounts, latency_problems, rate_problems


def test_a_loop_at_1_3_hz_when_50_is_expected_is_not_ok() -> None:
    """Below the tolerance: WARN; no event in the window after the start: ERROR; else ok."""
    warn, error = rate_problems(1.3, 7, 50.0, 0.1, started=True)
    assert warn and not error and '1.3 Hz' in warn[0] and '45.0 Hz' in warn[0]
    assert rate_problems(46.0, 230, 50.0, 0.1, started=True) == ([], [])
    assert rate_problems(0.0, 0, 50.0, 0.1, started=True)[1], 'a stall is an ERROR'
    assert rate_problems(0.0, 0, 50.0, 0.1, started=False) == ([], []), 'not started yet'
    # A lockstep simulation may run faster than real time; a realtime loop may not.
    assert rate_problems(300.0, 1500, 25.0, 0.1, started=True) == ([], [])
    assert rate_problems(300.0, 1500, 25.0, 0.1, started=True, upper=True)[0]


def test_latency_thresholds_warn_then_error_and_nothing_measured_says_nothing() -> None:
    """p99 above warn_ms: WARN; above error_ms: ERROR (only); nan: no line."""
    assert latency_problems(30.0, 40.0, 200.0, 'o -> a') == ([], [])
    assert latency_problems(50.0, 40.0, 200.0, 'o -> a')[0] == ['o -> a p99 50 ms > 40 ms']
    assert latency_problems(1800.0, 40.0, 200.0, 'o -> a') == (
        [], ['o -> a p99 1800 ms > 200 ms'])
    assert latency_problems(math.nan, 40.0, 200.0, 'o -> a') == ([], [])


def test_counts_warn_per_window_and_clear_when_the_cause_has() -> None:
    """One event WARNs for one window, not for the rest of the run."""
    window = WindowCounts(window=0.2)
    counts = {'timeouts': 0, 'steps': 10}
    assert window.problems(window.delta(counts), ['timeouts']) == []
    counts['timeouts'] = 1
    assert window.problems(window.delta(counts), ['timeouts']) == [
        '1 timeouts in the last 0.2 s']
    time.sleep(0.25)
    window.delta(counts)  # the window moves past the event
    time.sleep(0.25)
    assert window.problems(window.delta(counts), ['timeouts']) == []
    assert counts['timeouts'] == 1, 'the run total is kept as it was'


def test_a_restart_is_believed_only_through_its_hello() -> None:
    """New nonce, same checkpoint, the key's proof: re-paired; anything else says why not."""
    import rclpy
    from zeus_msgs.msg import PairingHello

    from zeus_ros.nodes.handshake import Hello, handshake_of

    from ros_harness import fresh_domain_id, ros_context

    agreed = Hello('/policy', 'n1', 'abc', frozenset({'01' * 16}))
    with ros_context(fresh_domain_id()) as context:
        node = rclpy.create_node('sim_bridge', context=context)
        try:
            handshake = handshake_of(node)
            assert handshake_of(node) is handshake
            new_gid = bytes.fromhex('02' * 16)
            assert 'no valid hello' in handshake.introduces(new_gid, '/policy', agreed)

            def heard(hello: Hello) -> str | None:
                handshake._on_hello(hello.to_msg(), new_gid)
                return handshake.introduces(new_gid, '/policy', agreed)

            gids = frozenset({new_gid.hex()})
            assert 'replay' in heard(Hello('/policy', 'n1', 'abc', gids))
            assert 'sha256' in heard(Hello('/policy', 'n2', 'def', gids))
            assert 'names /other' in heard(Hello('/other', 'n2', 'abc', gids))
            assert heard(Hello('/policy', 'n2', 'abc', gids)) is None
            handshake.key = b'launch key'
            handshake._by_gid.clear()
            assert 'no valid hello' in heard(Hello('/policy', 'n2', 'abc', gids))
            assert 'no valid hello' in heard(
                Hello('/policy', 'n2', 'abc', gids).signed(b'other'))
            assert heard(Hello('/policy', 'n2', 'abc', gids).signed(b'launch key')) is None
            assert handshake.refused == 2, 'the two unproven hellos were refused on receipt'
            handshake._on_hello(PairingHello(), new_gid)
            assert handshake.malformed == 1
        finally:
            node.destroy_node()


def test_hellos_are_checked_on_receipt_and_their_senders_named() -> None:
    """Relayed, claiming another process's publishers, unproven: refused on receipt.

    Counted, never stored (the pair's hello stays the genuine one), the sender named in full.
    """
    import rclpy

    from zeus_ros.nodes.handshake import Hello, handshake_of, pairing_diagnostics

    from ros_harness import fresh_domain_id, ros_context

    key = b'launch key'
    policy = bytes.fromhex('aa' * 12 + '00001303')  # the policy's process, one publisher
    poisoner = bytes.fromhex('bb' * 12 + '00001303')  # the same entity id, another process
    genuine = Hello('/policy', 'n1', 'abc', frozenset({policy.hex()}), pid=42).signed(key)
    with ros_context(fresh_domain_id()) as context:
        node = rclpy.create_node('sim_bridge', context=context)
        try:
            handshake = handshake_of(node)
            handshake.key = key
            handshake._on_hello(genuine.to_msg(), policy)
            assert handshake.hello_of(policy) == genuine
            relayed = Hello('/policy', 'n9', 'f' * 64, genuine.gids, genuine.proof, 42)
            claiming = Hello('/policy', 'n9', 'f' * 64, frozenset({policy.hex(),
                                                                  poisoner.hex()})).signed(key)
            unproven = Hello('/policy', 'n9', 'f' * 64, frozenset({poisoner.hex()}), pid=7)
            for hello in (relayed, claiming, unproven):
                handshake._on_hello(hello.to_msg(), poisoner)
            assert handshake.hello_of(policy) == genuine, 'a refused hello overwrote the pair'
            assert handshake.hello_of(poisoner) is None
            assert handshake.refused == 3
            why = handshake.check(relayed, poisoner)
            assert why is not None and 'relayed' in why
            why = handshake.check(claiming, poisoner)
            assert why is not None and 'another process' in why
            why = handshake.check(unproven, poisoner)
            assert why is not None and 'proof' in why
            values, errors = pairing_diagnostics(node)
            assert values == {'pairing': 'keyed', 'hellos_refused': 3}
            assert len(errors) == 1 and poisoner.hex() in errors[0], errors
            assert 'its hello claims to be /policy pid 7' in errors[0], errors
            handshake.key = b''
            assert pairing_diagnostics(node)[0]['pairing'] == 'unkeyed'
            assert handshake.check(unproven, poisoner) is None, 'unkeyed: its own GIDs only'
        finally:
            node.destroy_node()


@pytest.mark.parametrize('fields', [{}, {'node': 'policy'}, {'nonce': ''},
                                    {'publisher_gids': []}, {'publisher_gids': ['01' * 15]},
                                    {'publisher_gids': ['zz' * 16]}])
def test_a_malformed_hello_is_never_trusted(fields: dict[str, object]) -> None:
    """Anything but a complete hello (name, nonce, 16-byte hex GIDs) is MalformedHelloError."""
    from zeus_msgs.msg import PairingHello

    from zeus_ros.nodes.handshake import Hello, MalformedHelloError

    complete = {'node': '/policy', 'nonce': 'n1', 'publisher_gids': ['01' * 16]}
    assert Hello.from_msg(PairingHello(**complete)).node == '/policy'
    with pytest.raises(MalformedHelloError):
        Hello.from_msg(PairingHello(**({**complete, **fields} if fields else {})))
