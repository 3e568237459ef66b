# One image for the api and the workers: `coach serve` or `coach worker` (see docker-compose.yml).
FROM python:3.11-slim-bookworm

# Headless rendering for pyrender (Mesa through EGL) and ffmpeg for video decoding.
RUN apt-get update \
    && apt-get install -y --no-install-recommends libegl1 libgl1-mesa-dri libglib2.0-0 ffmpeg \
    && rm -rf /var/lib/apt/lists/*

ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_NO_CACHE_DIR=1 \
    PYOPENGL_PLATFORM=egl \
    COACH_DATA_DIR=/data

WORKDIR /app
# Dependencies first, so a code change does not reinstall them.
COPY pyproject.toml README.md ./
COPY engine/__init__.py engine/__init__.py
COPY app/__init__.py app/__init__.py
COPY worker/__init__.py worker/__init__.py
RUN pip install ".[render,worker,api,viewer]" && pip uninstall -y motion-coach
COPY engine engine
COPY worker worker
COPY app app
COPY web web
RUN pip install --no-deps ".[render,worker,api,viewer]"

RUN useradd --create-home --uid 1000 coach && mkdir -p /data && chown coach /data
USER coach
VOLUME ["/data"]
EXPOSE 8000
CMD ["coach", "serve", "--host", "0.0.0.0"]
