# One image for every service; compose.yaml gives each service its own command.
FROM python:3.11-slim-bookworm

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    MUJOCO_GL=osmesa

# libosmesa6: MuJoCo's offscreen renderer without a GPU. libgl1/libglib2.0-0: OpenCV and MuJoCo.
RUN apt-get update \
 && apt-get install -y --no-install-recommends libosmesa6 libgl1 libglib2.0-0 \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /app
COPY pyproject.toml README.md ./
COPY libs ./libs
COPY services ./services
RUN pip install .

# Recordings and user data live in volumes, never in the image.
VOLUME ["/app/recordings"]
CMD ["asibot", "--help"]
