"""One room per command (fly, learn, report, identify, study), each beside its view."""
