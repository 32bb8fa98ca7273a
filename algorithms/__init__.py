"""One Processing algorithm per pipeline step, each a thin wrapper over one core call."""
