"""Pipelines composed from the stages of ``i2v_loc.stages`` (composition only, no stage logic)."""
