"""What a checkpoint does: evaluation, diagnostics, probe, read-out, reports, export."""
