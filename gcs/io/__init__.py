"""Files and formats: profiles, run directories, trial records and motion-capture samples."""
