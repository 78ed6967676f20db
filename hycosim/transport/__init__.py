"""How frames travel: Zenoh sessions, keys, inbox and security, and the in-process bus, with
one interface for each side (the relay's in ``server_side``)."""
