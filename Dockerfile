# One image for every service of the stack: vda-broker, vda-master, vda-vehicle, vda-demo.
FROM python:3.11-slim

WORKDIR /app
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1

COPY pyproject.toml README.md ./
COPY src ./src
COPY schemas ./schemas
RUN pip install .

COPY config ./config

# 1883: MQTT (vda-broker), 8050: master HTTP API
EXPOSE 1883 8050
CMD ["vda-demo", "--help"]
