"""Bags and the data in them: schema, writing, durable recording, recovery, ingest, replay."""
