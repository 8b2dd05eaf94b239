# The ecodrive image: the advisory service (`ecodrive serve`), the SPaT feed and log player (`python -m spat_feed`), and Debian's mosquitto (the MQTT broker of docker-compose.yml).
FROM python:3.11-slim
RUN apt-get update && apt-get install -y --no-install-recommends espeak-ng curl mosquitto && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml README.md ./
COPY advisory advisory
COPY spat_feed spat_feed
COPY server server
COPY replay replay
COPY ecodrive ecodrive
RUN pip install --no-cache-dir .
RUN useradd --create-home ecodrive && mkdir -p /app/cache && chown ecodrive /app/cache
USER ecodrive
ENV ECO_TABLES_DIR=/app/cache/tables NUMBA_CACHE_DIR=/app/cache/numba
EXPOSE 8000 8765
CMD ["ecodrive", "serve", "--host", "0.0.0.0", "--port", "8000"]
