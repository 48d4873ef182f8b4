# isac-mission: one image for every role (sim, serve, run, simulate).
FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 MAVLINK20=1 MAVLINK_DIALECT=common
WORKDIR /app
COPY pyproject.toml README.md ./
COPY isac_mission ./isac_mission
COPY sim ./sim
COPY config ./config
RUN pip install --no-cache-dir .
ENTRYPOINT ["isac-mission"]
