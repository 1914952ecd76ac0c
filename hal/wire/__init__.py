"""The HAL's wire: the message format and key expressions (:mod:`.protocol`, no Zenoh), and the Zenoh
sessions that carry them (:mod:`.session`)."""
