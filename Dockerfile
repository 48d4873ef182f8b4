# isac-mission: one image for every role (sim, serve, run, simulate).
FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 MAVLINK20=1 MAVLINK_DIALECT=common
WORKDIR /app
COPY pyproject.toml README.md LICENSE constraints.txt ./
COPY isac_mission ./isac_mission
COPY sim ./sim
# The scenarios ship inside the package: `isac-mission serve paper` needs no config folder.
RUN pip install --no-cache-dir -c constraints.txt .
ENTRYPOINT ["isac-mission"]
