# i2v-loc yard service. Build: docker build -t i2v-loc .   Run: docker run -p 8000:8000 i2v-loc
FROM python:3.11-slim

# open3d needs these at import time
RUN apt-get update \
    && apt-get install -y --no-install-recommends libusb-1.0-0 libgl1 libgomp1 \
    && rm -rf /var/lib/apt/lists/*

RUN useradd --create-home --uid 1000 i2v
WORKDIR /app
COPY pyproject.toml setup.py README.md ./
COPY i2v_loc ./i2v_loc
COPY service ./service
# The sample recordings and suites go into the package (bench and sim --suite find them there).
COPY samples ./samples
RUN pip install --no-cache-dir . && rm -rf /root/.cache /app/i2v_loc /app/service /app/samples
COPY params ./params
# The front end's compiled kernels (numba) are built once here, into a cache the service user reads
ENV NUMBA_CACHE_DIR=/app/.numba_cache
RUN python -c "from i2v_loc.stages import kernels; kernels.warm_up()"
RUN chown -R i2v /app

USER i2v
ENV PYTHONUNBUFFERED=1
EXPOSE 8000
# Inside a container the service must listen on all interfaces to be reachable through -p.
HEALTHCHECK --interval=15s --timeout=3s --start-period=60s --retries=3 \
    CMD python -c "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/api/v1/health', timeout=2).status == 200 else 1)"
# Reads are open inside the container network (--allow-open-reads); put TLS in front (a reverse proxy) or
# pass --ssl-keyfile/--ssl-certfile, else the write token travels in clear text.
CMD ["i2v-loc", "serve", "--source", "sim:docking", "--host", "0.0.0.0", "--allow-open-reads", "--port", "8000", "--params", "/app/params/service.yaml"]
