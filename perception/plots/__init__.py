"""Pictures of perception results: error against angles and size, estimates drawn on a scene."""
