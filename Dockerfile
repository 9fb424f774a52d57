# One image for every service; compose.yaml gives each service its own command.

# The web page's npm packages, pinned in package-lock.json, bundled once (as ./bootstrap does).
FROM node:20-bookworm-slim AS web
WORKDIR /web
COPY services/web/frontend/package.json services/web/frontend/package-lock.json services/web/frontend/build.mjs ./frontend/
COPY services/web/frontend/entries ./frontend/entries
RUN npm ci --prefix frontend --no-audit --no-fund && node frontend/build.mjs

FROM python:3.11-slim-bookworm

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    MUJOCO_GL=osmesa

# libosmesa6: MuJoCo's offscreen renderer without a GPU. libgl1/libglib2.0-0: OpenCV and MuJoCo.
RUN apt-get update \
 && apt-get install -y --no-install-recommends libosmesa6 libgl1 libglib2.0-0 \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /app
COPY libs ./libs
COPY services ./services
COPY --from=web /web/asibot/web/static/vendor ./services/web/asibot/web/static/vendor
# Every package of the `asibot` namespace but the test helpers (libs/testing).
RUN pip install ./libs/common ./libs/cli ./services/*/

# Recordings and user data live in volumes, never in the image.
ENV ASIBOT_DATA=/data
VOLUME ["/app/recordings", "/data"]
CMD ["asibot", "--help"]
