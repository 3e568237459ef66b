"""The FastAPI service: uploads, jobs, results, coach review, REST API for clubs."""
