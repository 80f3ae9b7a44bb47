"""Flight logs: the JSON-lines writer and reader, summaries and plots."""
