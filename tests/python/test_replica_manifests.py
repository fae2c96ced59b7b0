"""The replica deployments (issue 30) parsed and checked, as far as this
machine can (no cluster, no Docker Hub): the Kubernetes StatefulSet with its
headless Service, gRPC health probes, read-only store volume and Prometheus
annotations; the three-replica compose file. The image itself is checked by
test_container.py."""

from __future__ import annotations

from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]


def _k8s() -> dict:
    documents = list(yaml.safe_load_all((REPO / "docker" / "k8s" / "outcore.yaml").read_text()))
    return {doc["kind"]: doc for doc in documents}


def test_statefulset_serves_through_a_headless_service():
    objects = _k8s()
    service, sts = objects["Service"], objects["StatefulSet"]
    assert service["spec"]["clusterIP"] == "None"
    assert sts["spec"]["serviceName"] == service["metadata"]["name"]
    assert sts["spec"]["replicas"] >= 2
    labels = sts["spec"]["template"]["metadata"]["labels"]
    assert service["spec"]["selector"].items() <= labels.items()
    assert sts["spec"]["selector"]["matchLabels"].items() <= labels.items()
    ports = {p["name"]: p["port"] for p in service["spec"]["ports"]}
    assert ports == {"grpc": 50051, "metrics": 9464}


def test_pods_probe_grpc_health_and_read_the_store_read_only():
    objects = _k8s()
    pod = objects["StatefulSet"]["spec"]["template"]
    [container] = pod["spec"]["containers"]
    args = container["args"]
    assert args[0] == "serve" and args[1].startswith("/data/")
    assert args[args.index("--listen") + 1] == "0.0.0.0:50051" and "--insecure" in args
    assert args[args.index("--metrics-listen") + 1] == "0.0.0.0:9464"
    for probe in ("readinessProbe", "livenessProbe"):
        assert container[probe]["grpc"]["port"] == 50051
    [mount] = container["volumeMounts"]
    assert mount["mountPath"] == "/data" and mount["readOnly"] is True
    [volume] = pod["spec"]["volumes"]
    claim = volume["persistentVolumeClaim"]
    assert claim["readOnly"] is True
    assert objects["PersistentVolumeClaim"]["metadata"]["name"] == claim["claimName"]
    assert objects["PersistentVolumeClaim"]["spec"]["accessModes"] == ["ReadOnlyMany"]
    annotations = pod["metadata"]["annotations"]
    assert annotations["prometheus.io/scrape"] == "true" and annotations["prometheus.io/port"] == "9464"
    assert pod["spec"]["securityContext"]["runAsNonRoot"] is True
    # SIGTERM drains for up to 10 s: the pod must be given longer.
    assert pod["spec"]["terminationGracePeriodSeconds"] > 10


def test_compose_runs_three_replicas_on_distinct_ports():
    compose = yaml.safe_load((REPO / "docker" / "compose-replicas.yaml").read_text())
    services = compose["services"]
    assert len(services) == 3
    published = set()
    for service in services.values():
        assert service["build"]["dockerfile"] == "docker/Dockerfile"
        assert service["command"][0] == "serve" and "--metrics-listen" in service["command"]
        assert any(v.endswith(":/data:ro") for v in service["volumes"])
        for port in service["ports"]:
            host, container = port.rsplit(":", 2)[1:]
            published.add(host)
            assert container in ("50051", "9464")
        assert "health" in service["healthcheck"]["test"]
    assert published == {"50051", "50052", "50053", "9464", "9465", "9466"}
