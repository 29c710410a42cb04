"""Flying through MAVSDK: connection, preflight, trials, landing; knows nothing of the maths."""
