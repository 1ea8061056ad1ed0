"""SETUP_SIGNING on the vehicle: a controller stores a MAVLink 2 signing key
(or turns signing off with an all-zero key).

From a stored key on, every packet the vehicle sends is signed and control
must carry a valid, fresh signature (``sitl.auth.ControlPolicy``). A key
given on the command line is locked: SETUP_SIGNING is then ignored. Only a
controller's SETUP_SIGNING reaches here (it is control, ``sitl.auth``).
"""

from __future__ import annotations

import time

from mavcore.link.signing import (SignatureVerifier, disable_outgoing_signing, enable_outgoing_signing,
                                  signing_timestamp)

from .flightstack import SEVERITY_INFO
from .vehicle_id import SYSTEM_ID


class SigningSetup:
    """The SETUP_SIGNING handler.

    Parameters
    ----------
    auth : sitl.auth.ControlPolicy
        Holds the verifier of incoming control.
    links : callable
        ``() -> list of links``: each link's encoder signs with the key, link
        index as its signing link id.
    say : callable
        The server's ``(severity, text)`` STATUSTEXT.
    """

    def __init__(self, auth, links, say) -> None:
        self.auth, self.links, self.say = auth, links, say

    def handlers(self) -> dict:
        """Message type -> ``(link, msg)`` handler, for the server's receive table."""
        return {"SETUP_SIGNING": self.on_setup_signing}

    def on_setup_signing(self, link, msg) -> None:
        if msg.target_system != SYSTEM_ID or self.auth.key_locked:
            return
        key = bytes(msg.secret_key)
        if not any(key):
            self.auth.set_signing(None)
            for l in self.links():
                disable_outgoing_signing(l.mav)
        else:
            ts = int(msg.initial_timestamp) or signing_timestamp(time.time())
            self.auth.set_signing(SignatureVerifier(key, ts))
            for i, l in enumerate(self.links()):
                enable_outgoing_signing(l.mav, key, i, ts)
        self.say(SEVERITY_INFO, "Signing " + ("disabled" if not any(key) else "key stored"))
