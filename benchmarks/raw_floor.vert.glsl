#version 460
// the raw floor: position only, the instance's transform from an instance-rate vertex buffer,
// view-projection pushed; no descriptor set, no fragment shader
layout(location = 0) in vec3 position;
layout(location = 1) in vec4 model0;
layout(location = 2) in vec4 model1;
layout(location = 3) in vec4 model2;
layout(location = 4) in vec4 model3;

layout(push_constant) uniform Push {
    mat4 view_proj;
};

void main() {
    gl_Position = view_proj * (mat4(model0, model1, model2, model3) * vec4(position, 1.0));
}
