"""The meshing pipeline: request -> strategies -> one solve -> one choice rule -> one result type (:mod:`.pipeline`)."""
