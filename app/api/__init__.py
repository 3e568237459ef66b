"""The HTTP API: dependencies, error shape and one router per resource."""
