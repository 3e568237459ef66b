"""Service infrastructure: settings, database, storage, queue seam, security, validation."""
