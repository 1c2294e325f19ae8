#pragma once
// Graph and geometry ops (autodiff/ops_graph.h): X(EnumName, function_stem). Add a line per new op.
#define LAYERSNET_GRAPH_OPS(X)
