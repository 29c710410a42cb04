"""Pure numerics: models, references, estimators, the update, the learner (no files or MAVSDK)."""
