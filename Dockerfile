# One image for every service; compose.yaml gives each service its own command.
#
#   docker build -t asibot:latest .
#
# Both bases are build arguments, pinned by digest for a reproducible build. A machine without
# an image registry passes its own (docs/docker.md): a Debian bookworm made with debootstrap,
# and a Node.js LTS image made from it.
ARG BASE=debian:bookworm-slim@sha256:7b140f374b289a7c2befc338f42ebe6441b7ea838a042bbd5acbfca6ec875818
ARG NODE=node:22-bookworm-slim@sha256:43ac6c60b8f89723f746e8a92ce91abd5017e627ce1ddfe4238355d3a30b772c

# ---- the web page's npm packages, pinned in package-lock.json, bundled once (as ./bootstrap does)
FROM ${NODE} AS web
WORKDIR /web
# Only what the downloads need from docker/ (a change to the rest rebuilds no download): the
# proxy's CA when there is one (the [t]: a pattern that may match nothing, beside a file that is there).
COPY docker/make-local-bases docker/extra-ca.cr[t] /tmp/docker/
COPY services/web/frontend/package.json services/web/frontend/package-lock.json services/web/frontend/build.mjs ./frontend/
COPY services/web/frontend/entries ./frontend/entries
# docker/extra-ca.crt: a download proxy's certificate authority, used here and never kept.
RUN if [ -f /tmp/docker/extra-ca.crt ]; then export NODE_EXTRA_CA_CERTS=/tmp/docker/extra-ca.crt; fi \
 && npm ci --prefix frontend --ignore-scripts --no-audit --no-fund --loglevel=error \
 && node frontend/build.mjs

# ---- the Python packages, from the lock file, into a virtual environment copied below whole
FROM ${BASE} AS python
COPY docker/make-local-bases docker/extra-ca.cr[t] /tmp/docker/
COPY requirements/build.txt requirements/runtime.txt /tmp/requirements/
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends python3 python3-venv ca-certificates \
 && rm -rf /var/lib/apt/lists/* \
 && python3 -m venv /opt/asibot \
 && if [ -f /tmp/docker/extra-ca.crt ]; then export PIP_CERT=/tmp/docker/extra-ca.crt; fi \
 && /opt/asibot/bin/pip install --no-cache-dir --disable-pip-version-check -q --require-hashes -r /tmp/requirements/build.txt \
 && /opt/asibot/bin/pip install --no-cache-dir --disable-pip-version-check -q --require-hashes -r /tmp/requirements/runtime.txt \
 && site=/opt/asibot/lib/python3.11/site-packages \
 && rm -rf $site/cmeel.prefix/include && find $site/cmeel.prefix -name '*.a' -delete
# (Pinocchio's wheels carry C++ headers and static libraries, 200 MB nothing here compiles against.)
# Our own packages, every one but the test helpers (libs/testing), built with the locked
# setuptools: nothing unlocked is fetched. The page's npm bundle goes in with the web package.
# (Few layers: vfs storage copies each one whole, and an image's layers are what changes.)
COPY --from=web /web/asibot/web/static/vendor /src/services/web/asibot/web/static/vendor
COPY . /src
RUN cd /src \
 && /opt/asibot/bin/pip install --no-cache-dir --disable-pip-version-check -q --no-deps --no-build-isolation \
        ./libs/common ./libs/cli $(ls -d services/*/) \
 && /opt/asibot/bin/pip check

# ---- what runs
FROM ${BASE}
# python3: the venv's interpreter. libosmesa6 libgl1 libglib2.0-0: MuJoCo's offscreen renderer
# and OpenCV without a GPU. libgomp1: pinocchio (kinematics). espeak-ng: spoken feedback.
# libportaudio2: a robot's own microphone. bubblewrap: the sandbox of user programs.
# libopenni2-0: OpenNI2 depth cameras (services/camera).
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
        python3 libosmesa6 libgl1 libglib2.0-0 libgomp1 espeak-ng libportaudio2 bubblewrap libopenni2-0 \
 && apt-get clean && rm -rf /var/lib/apt/lists/* /var/cache/apt/archives/*.deb \
 && useradd --create-home --uid 1000 --shell /usr/sbin/nologin asibot \
 && mkdir -p /app/recordings /data /run/asibot-router \
 && chown asibot:asibot /app/recordings /data /run/asibot-router \
 && chmod 0700 /app/recordings /data \
 && chmod 0711 /run/asibot-router
ENV PATH=/opt/asibot/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    MUJOCO_GL=osmesa \
    ASIBOT_DATA=/data
WORKDIR /app
USER asibot
# Recordings and user data live outside the image: compose.yaml binds the checkout's recordings/
# and the named volume asibot-data at /data, which copies this 0700 /data on first use. No VOLUME
# line: it gave every container an anonymous volume for each path (18 in the sim profile), left
# behind by every `docker compose down` (docs/docker.md).
CMD ["asibot", "--help"]
# The recorder's entrypoint and every service's healthcheck (compose.yaml).
COPY docker/bin/ /usr/local/bin/
# Last: the one layer a change of our code rebuilds (the settings above are cached).
COPY --from=python /opt/asibot /opt/asibot
