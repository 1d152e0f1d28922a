#include "lic/Contrast.h"
#include "lic/Engine.h"
#include "lic/Noise.h"
#include "TestFields.h"
#include <cstdio>
using namespace lic; static double argc_len=20; static double g_maxs=0;
struct SmoothTex { static constexpr int kChannels=1;
  void sample(const openvdb::Vec3d& p, float* o) const { float g[3]; sampleGradient(p,o,g);} 
  void sampleGradient(const openvdb::Vec3d& p, float* o, float* g) const {
    double f=0.7; o[0]=float(0.5+0.25*std::sin(f*p[0])*std::cos(f*p[1]+1)*std::sin(f*p[2]+2));
    if(g){g[0]=float(0.25*f*std::cos(f*p[0])*std::cos(f*p[1]+1)*std::sin(f*p[2]+2));
    g[1]=float(-0.25*f*std::sin(f*p[0])*std::sin(f*p[1]+1)*std::sin(f*p[2]+2));
    g[2]=float(0.25*f*std::sin(f*p[0])*std::cos(f*p[1]+1)*std::cos(f*p[2]+2));}}
};
struct BlurTex { static constexpr int kChannels=1; openvdb::Coord lo; int dx,dy,dz; std::vector<float> d;
  BlurTex(const openvdb::CoordBBox& bb, int seed, float w){ lo=bb.min()-openvdb::Coord(3); openvdb::Coord hi=bb.max()+openvdb::Coord(3); dx=hi[0]-lo[0]+1;dy=hi[1]-lo[1]+1;dz=hi[2]-lo[2]+1; d.resize(size_t(dx)*dy*dz);
    for(int i=0;i<dx;i++)for(int j=0;j<dy;j++)for(int k=0;k<dz;k++) d[(size_t(i)*dy+j)*dz+k]=whiteNoise(seed,lo[0]+i,lo[1]+j,lo[2]+k);
    float a=w, b=1-2*w; std::vector<float> t=d;
    auto id=[&](int i,int j,int k){return (size_t(i)*dy+j)*dz+k;};
    for(int i=1;i<dx-1;i++)for(int j=0;j<dy;j++)for(int k=0;k<dz;k++) t[id(i,j,k)]=a*d[id(i-1,j,k)]+b*d[id(i,j,k)]+a*d[id(i+1,j,k)]; d=t;
    for(int i=0;i<dx;i++)for(int j=1;j<dy-1;j++)for(int k=0;k<dz;k++) t[id(i,j,k)]=a*d[id(i,j-1,k)]+b*d[id(i,j,k)]+a*d[id(i,j+1,k)]; d=t;
    for(int i=0;i<dx;i++)for(int j=0;j<dy;j++)for(int k=1;k<dz-1;k++) t[id(i,j,k)]=a*d[id(i,j,k-1)]+b*d[id(i,j,k)]+a*d[id(i,j,k+1)]; d=t; }
  float at(int i,int j,int k)const{ i=std::clamp(i-lo[0],0,dx-1);j=std::clamp(j-lo[1],0,dy-1);k=std::clamp(k-lo[2],0,dz-1); return d[(size_t(i)*dy+j)*dz+k];}
  void sample(const openvdb::Vec3d& p, float* o) const { sampleGradient(p,o,nullptr);} 
  void sampleGradient(const openvdb::Vec3d& p, float* out, float* grad) const {
        const double fx0 = std::floor(p[0]), fy0 = std::floor(p[1]), fz0 = std::floor(p[2]);
        const int i = int(fx0), j = int(fy0), k = int(fz0);
        const float fx = float(p[0] - fx0), fy = float(p[1] - fy0), fz = float(p[2] - fz0);
        float n[2][2][2];
        for (int a = 0; a < 2; ++a) for (int b = 0; b < 2; ++b) for (int c = 0; c < 2; ++c) n[a][b][c] = at(i + a, j + b, k + c);
        auto lerp = [](float u, float v, float t) { return u + (v - u) * t; };
        const float c00 = lerp(n[0][0][0], n[0][0][1], fz), c01 = lerp(n[0][1][0], n[0][1][1], fz);
        const float c10 = lerp(n[1][0][0], n[1][0][1], fz), c11 = lerp(n[1][1][0], n[1][1][1], fz);
        const float c0 = lerp(c00, c01, fy), c1 = lerp(c10, c11, fy);
        out[0] = lerp(c0, c1, fx);
        if (grad) { grad[0] = c1 - c0; grad[1] = lerp(c01 - c00, c11 - c10, fx);
            const float d00 = n[0][0][1] - n[0][0][0], d01 = n[0][1][1] - n[0][1][0];
            const float d10 = n[1][0][1] - n[1][0][0], d11 = n[1][1][1] - n[1][1][0];
            grad[2] = lerp(lerp(d00, d01, fy), lerp(d10, d11, fy), fx); } }
};
template<class T> void run(const char* name, const T& tex, int n, int cr){
    VelocityField field(lictest::abcField(n)); OutputDomain domain(field,2);
    LicSettings s; s.length=argc_len; s.maxStreamline=g_maxs; s.engine=EngineType::Naive; s.coveredRun=cr; auto a=convolve(field,domain,tex,s);
    s.engine=EngineType::Fast; auto b=convolve(field,domain,tex,s);
    double sa=0,sb=0,saa=0,sbb=0,sab=0,N=0;
    for(size_t i=0;i<a.channels[0].size();++i){ if(!domain.isActive(i))continue; double x=a.channels[0][i],y=b.channels[0][i]; sa+=x;sb+=y;saa+=x*x;sbb+=y*y;sab+=x*y;N++;}
    double ca=saa/N-sa/N*sa/N, cb=sbb/N-sb/N*sb/N;
    std::printf("%s cr=%d corr %.4f  naive %.2fs fast %.2fs spv %.2f streamlines %llu rounds %d\n",name,cr,(sab/N-sa/N*sb/N)/std::sqrt(ca*cb),a.stats.seconds,b.stats.seconds,b.stats.samplesPerVoxel(),(unsigned long long)b.stats.streamlines,b.stats.rounds);
}
int main(int argc,char**argv){ g_maxs=argc>4?atof(argv[4]):0; int N=argc>3?atoi(argv[3]):32; argc_len=argc>2?atof(argv[2]):20; int cr=argc>1?atoi(argv[1]):8; run("smooth",SmoothTex{},N,cr); { VelocityField field(lictest::abcField(N)); OutputDomain domain(field,2); run("noise",NoiseTexture(7,domain.indexBBox(),NoiseFilter::None),N,cr); run("binomial",NoiseTexture(7,domain.indexBBox()),N,cr);}
 { VelocityField field(lictest::abcField(N)); OutputDomain domain(field,2); run("blur0.25",BlurTex(domain.indexBBox(),7,0.25f),N,cr);} }
