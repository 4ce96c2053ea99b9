"""The bag format: what a recording holds and how it is written, closed and recovered.

One package for the two sides that must agree to the byte: the recorder node writes bags live
(durable.py over writer.py, with schema.py's topics, types and QoS), and the offline tools write
the same bags in-process (offline/rollout.py) and read them back (offline/data/ingest.py, with
cdr_columns.py and mcap_file.py); recording.py says which folders of a recording are bags and
which of its splits are closed (ingest, `zeus recover`, the continual trainer). It imports
neither the nodes nor offline/, so both can use it.
"""
