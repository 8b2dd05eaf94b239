# The ecodrive image: the advisory service (`ecodrive serve`), the SPaT feed and log player (`python -m spat_feed`);
# Debian's mosquitto (the MQTT broker), redis-server (the shared trip store) and haproxy (the load balancer) for docker-compose.yml.
FROM python:3.11-slim
RUN apt-get update && apt-get install -y --no-install-recommends espeak-ng curl mosquitto redis-server haproxy && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml README.md ./
COPY advisory advisory
COPY spat_feed spat_feed
COPY server server
COPY replay replay
COPY ecodrive ecodrive
COPY deploy deploy
RUN pip install --no-cache-dir .
RUN useradd --create-home ecodrive && mkdir -p /app/cache /app/redis /app/mqtt-auth && chown ecodrive /app/cache /app/redis /app/mqtt-auth
USER ecodrive
ENV ECO_TABLES_DIR=/app/cache/tables NUMBA_CACHE_DIR=/app/cache/numba
EXPOSE 8000 8765
CMD ["ecodrive", "serve", "--host", "0.0.0.0", "--port", "8000"]
