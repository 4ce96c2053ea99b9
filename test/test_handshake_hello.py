"""The pairing hello as zeus_msgs/msg/PairingHello (issue 48, item 5).

Why: the hello used to be JSON in a std_msgs/String, invisible to `ros2 interface show`. As
a message of its own the middleware checks its types, but not its contents: a hello with an
empty name or nonce, no GID, or GIDs of the wrong size must still be refused on receipt,
counted and named, never stored and never crash the node. The proof must cover exactly the
fields it covered as JSON, so keys and proofs of both forms agree.
"""

from __future__ import annotations

import hashlib
import hmac
import json


def test_the_message_round_trips_and_its_proof_covers_the_same_fields() -> None:
    """to_msg / from_msg keep every field; the proof is the HMAC of the old JSON body."""
    from zeus_ros.nodes.handshake import Hello

    key = b'launch key'
    gids = frozenset({'bb' * 12 + '00001303', 'bb' * 12 + '00001203'})
    hello = Hello('/r1/policy', 'n1', 'ab' * 32, gids, pid=4242).signed(key)
    msg = hello.to_msg()
    assert list(msg.publisher_gids) == sorted(gids)
    assert (msg.node, msg.nonce, msg.checkpoint_sha256, msg.pid) == \
        ('/r1/policy', 'n1', 'ab' * 32, 4242)
    assert Hello.from_msg(msg) == hello and Hello.from_msg(msg).verified(key)
    body = json.dumps(['/r1/policy', 'n1', 'ab' * 32, sorted(gids), 4242]).encode()
    assert msg.proof == hmac.new(key, body, hashlib.sha256).hexdigest()
    for field, value in (('node', '/r1/other'), ('nonce', 'n2'), ('checkpoint_sha256', ''),
                         ('pid', 1), ('publisher_gids', sorted(gids)[:1])):
        changed = hello.to_msg()
        setattr(changed, field, value)
        assert not Hello.from_msg(changed).verified(key), f'the proof does not cover {field}'


def test_a_malformed_hello_message_is_refused_counted_and_named() -> None:
    """Wrong GID sizes, empty fields: each refused and counted on receipt, none stored.

    The node goes on: a genuine hello after them is stored, and /diagnostics names the
    sender of the malformed ones.
    """
    import rclpy
    from zeus_msgs.msg import PairingHello

    from zeus_ros.nodes.handshake import Hello, handshake_of, pairing_diagnostics

    from ros_harness import fresh_domain_id, ros_context

    sender = bytes.fromhex('aa' * 12 + '00001303')
    own = sender.hex()
    good = {'node': '/policy', 'nonce': 'n1', 'checkpoint_sha256': 'abc', 'pid': 7,
            'publisher_gids': [own]}
    malformed = [
        {'publisher_gids': [own, own[:-2]]},  # 15 bytes
        {'publisher_gids': [own, own + '00' * 8]},  # 24 bytes (a pre-Jazzy GID's storage)
        {'publisher_gids': [own.upper()]},  # not as the middleware's GID reads
        {'publisher_gids': [own, 'not hex' * 5]},
        {'publisher_gids': []},
        {'publisher_gids': ['']},
        {'node': ''},
        {'node': 'policy'},  # not a fully qualified name
        {'nonce': ''},
        {},  # every field empty
    ]
    with ros_context(fresh_domain_id()) as context:
        node = rclpy.create_node('sim_bridge', context=context)
        try:
            handshake = handshake_of(node)
            for fields in malformed:
                msg = PairingHello(**({**good, **fields} if fields else {}))
                handshake._on_hello(msg, sender)
            assert handshake.malformed == handshake.refused == len(malformed)
            assert handshake.hello_of(sender) is None, 'a malformed hello was stored'
            values, errors = pairing_diagnostics(node)
            assert values['hellos_refused'] == len(malformed)
            assert len(errors) == 1 and own in errors[0] and 'malformed' in errors[0], errors
            handshake._on_hello(PairingHello(**good), sender)
            assert handshake.hello_of(sender) == Hello('/policy', 'n1', 'abc',
                                                       frozenset({own}), pid=7)
            assert handshake.refused == len(malformed), 'the genuine hello was refused'
        finally:
            node.destroy_node()
