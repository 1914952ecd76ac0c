"""Robot side of the HAL: what a robot process serves (:mod:`.served`), the firmware safety
(:mod:`.firmware`), the Zenoh server (:mod:`.server`, its config in :mod:`.config`) and real-time
scheduling (:mod:`.realtime`)."""
