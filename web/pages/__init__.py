"""Browser pages of the motion coach: HTML pages (:mod:`.html`), the JSON endpoints they call
(:mod:`.api`, session-cookie auth) and file helpers (:mod:`.media`)."""
