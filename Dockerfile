# isac-mission: one image for every role (sim, serve, run, simulate).
# BASE: the official python:3.11-slim by default; where Docker Hub cannot be reached,
# scripts/build-base-image.sh builds a stand-in from Debian's packages (docs/deployment.md, "Docker Compose").
ARG BASE=python:3.11-slim
FROM ${BASE}
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 MAVLINK20=1 MAVLINK_DIALECT=common
WORKDIR /app
COPY pyproject.toml README.md LICENSE constraints.txt ./
COPY isac_mission ./isac_mission
COPY sim ./sim
# The scenarios ship inside the package: `isac-mission serve paper` needs no config folder.
# The service runs as an unprivileged user; /data (the compose file's volume) is its own.
RUN pip install --no-cache-dir -c constraints.txt . \
    && useradd --system --uid 10001 --home-dir /data --shell /usr/sbin/nologin isac \
    && mkdir -p /data && chown isac /data
USER isac
WORKDIR /data
# Healthy when the ground service plans: its console (127.0.0.1:8080) has seen a plan. Only
# `serve` and `run` with the console on pass it; the compose file turns it off for `world`.
HEALTHCHECK --interval=10s --timeout=5s --start-period=120s --retries=3 CMD ["python3", "-c", \
    "import json, sys, urllib.request as u; s = json.load(u.urlopen('http://127.0.0.1:8080/api/snapshot', timeout=4)); sys.exit(0 if 'plan' in s['latest'] else 1)"]
ENTRYPOINT ["isac-mission"]
