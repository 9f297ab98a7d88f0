# The service image: `docker build -t ctp . && docker run -p 8000:8000 -v ctp-data:/data ctp`
# then open http://127.0.0.1:8000/ (dashboard) or /docs (API). Jobs are kept in /data.
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /app
# the package (pinned dependencies from pyproject.toml), then the example scenes it serves
COPY pyproject.toml README.md ./
COPY analysis ./analysis
COPY planner ./planner
COPY sim ./sim
COPY api ./api
COPY ctp ./ctp
COPY examples ./examples
RUN pip install . \
    && useradd --create-home --uid 10001 ctp \
    && mkdir -p /data && chown ctp /data

USER ctp
ENV CTP_DATABASE_URL=sqlite:////data/ctp-jobs.db \
    CTP_EXAMPLES_DIR=/app/examples \
    CTP_DATA_DIR=/data/ctp-data \
    CTP_ANALYSIS_WORKERS=2 \
    CTP_JOB_WORKERS=1
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s \
    CMD ["python", "-c", "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/health', timeout=4)"]
# one server process (its job runner owns the job workers); scale with CTP_*_WORKERS or Ray
CMD ["uvicorn", "api.main:app", "--host", "0.0.0.0", "--port", "8000"]
