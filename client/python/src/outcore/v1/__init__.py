"""Generated gRPC stubs for outcore.v1 (scene_query_pb2, scene_query_pb2_grpc).

Written at build time from proto/outcore/v1/scene_query.proto by setup.py; the
package path matches the proto's so the generated imports resolve.
"""
