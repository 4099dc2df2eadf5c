# syntax=docker/dockerfile:1.7
# skyfix server image: multi-stage, runs as a non-root user, default navigation database built in.
#
#   docker build -t skyfix .
#   docker run --rm -p 8000:8000 -e SKYFIX_API_KEY="$(openssl rand -hex 24)" skyfix
#
# The container binds 0.0.0.0, so SKYFIX_API_KEY is required (skyfix serve refuses to start
# without it). Other settings: SKYFIX_WORKERS, SKYFIX_CAMERAS, SKYFIX_MAX_* (docs/api.md). To serve
# another database, mount it read-only and point SKYFIX_DB_PATH at it:
#   docker run ... -v /srv/navdb:/navdb:ro -e SKYFIX_DB_PATH=/navdb skyfix

ARG PYTHON_VERSION=3.11

# ---- build: dependencies (cached layer), then the project, then the default database ---------
FROM python:${PYTHON_VERSION}-slim AS build
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PYTHONDONTWRITEBYTECODE=1
RUN python -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH
WORKDIR /src

# Dependencies only: this layer is rebuilt only when pyproject.toml changes.
COPY pyproject.toml README.md ./
RUN python -c "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']))" \
        > /tmp/requirements.txt
RUN --mount=type=cache,target=/root/.cache/pip pip install -r /tmp/requirements.txt

COPY service ./service
COPY client ./client
RUN pip install --no-deps --no-cache-dir . && python -m compileall -q /opt/venv

# The default navigation database, built once here from the bundled Hipparcos catalogue.
ENV SKYFIX_DB_DIR=/opt/skyfix/db
# Solving once per method also compiles numba's kernels into NUMBA_CACHE_DIR, which the
# runtime stage copies (numba reuses it when the CPU matches, else compiles in memory).
ENV NUMBA_CACHE_DIR=/opt/skyfix/numba
RUN python -c "from service.core.navdb import ensure_default_database, open_database; \
from service.core.pipeline import warm_up; warm_up(open_database(ensure_default_database()))"

# ---- runtime ---------------------------------------------------------------------------------
FROM python:${PYTHON_VERSION}-slim AS runtime
# A home the user owns (numba, like other libraries, may write under $HOME), and the numba cache
# owned by the user: numba writes an index beside what it compiled, and compiles again on a CPU
# unlike the build machine's. Without both, every cached kernel fails at import as non-root
# ("cannot cache function ...: no locator available"). The code and the database stay root's
# (read-only to the server); tests/cli/test_serve_nonroot.py starts `skyfix serve` that way.
RUN useradd --system --uid 10001 --user-group --create-home --home-dir /home/skyfix \
        --shell /usr/sbin/nologin skyfix
COPY --from=build /opt/venv /opt/venv
COPY --from=build /opt/skyfix/db /opt/skyfix/db
COPY --from=build --chown=skyfix:skyfix /opt/skyfix/numba /opt/skyfix/numba
ENV PATH=/opt/venv/bin:$PATH \
    HOME=/home/skyfix \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    SKYFIX_HOST=0.0.0.0 \
    SKYFIX_PORT=8000 \
    SKYFIX_DB_DIR=/opt/skyfix/db \
    SKYFIX_DB_PATH=/opt/skyfix/db/default \
    NUMBA_CACHE_DIR=/opt/skyfix/numba
USER skyfix:skyfix
WORKDIR /opt/skyfix
EXPOSE 8000
# /v1/health needs no API key; python is in the image, curl is not.
HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/v1/health' % os.environ.get('SKYFIX_PORT', '8000'), timeout=4)"]
ENTRYPOINT ["skyfix", "serve"]
